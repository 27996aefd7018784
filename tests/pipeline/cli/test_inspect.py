"""`fleetcal inspect`: text and JSON output, config file, and clean failures (exit 2)."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from typer.testing import CliRunner, Result

from pipeline.cli import inspect as inspect_cli
from pipeline.io.writer import WriterFormat
from tests.pipeline.io.recordings import Spec, write_recording

app = typer.Typer()
inspect_cli.register(app)
app.command("noop", hidden=True)(lambda: None)  # keeps `inspect` a named sub-command


def run(*args: str) -> Result:
    return CliRunner().invoke(app, ["inspect", *args])


def _recording(tmp_path: Path, **spec: object) -> Path:
    path = tmp_path / "rec.bag"
    write_recording(path, WriterFormat.ROS1, Spec(stops=2, points=60, **spec))  # type: ignore[arg-type]
    return path


def test_json_output(tmp_path: Path) -> None:
    result = run(str(_recording(tmp_path)), "--json")

    assert result.exit_code == 0, result.output
    document = json.loads(result.stdout)
    assert {"format", "lidars", "stops", "base_frame", "warnings"} <= document.keys()
    assert document["format"] == "ros1"
    assert [set(lidar) >= {"frame", "topic", "points"} for lidar in document["lidars"]] == [
        True,
        True,
    ]
    assert [set(stop) >= {"start", "end"} for stop in document["stops"]] == [True, True]


def test_text_output(tmp_path: Path) -> None:
    result = run(str(_recording(tmp_path)))

    assert result.exit_code == 0, result.output
    assert "format      ros1 (ros1 storage)" in result.stdout
    assert "lidar_rear   /lidar_rear/points  51 scans, 0.6 k points/s" in result.stdout
    assert (
        "clocks      trajectory header stamps 0.000 s behind the log time; LiDARs on the same "
        "clock\n"
        "stops       2 (mean 2.00 s; times from the recording's start; scans wholly inside "
        "each, per LiDAR)\n"
        "                 span            duration  lidar_front  lidar_rear\n"
        "    0     0.00 -    2.00 s    2.00 s           19          19\n"
        "    1     3.00 -    5.00 s    2.00 s           19          19\n"
    ) in result.stdout
    assert "- too few stops: 2 found" in result.stdout


def test_text_output_shows_a_lidar_on_another_clock_and_short_stops(tmp_path: Path) -> None:
    behind = -120 * 86_400 * 10**9
    offsets = {"/lidar_front/points": behind}
    path = _recording(tmp_path, dwell_s=0.4, t0=1.7e9, header_clock_offset_ns=offsets)

    result = run(str(path))

    assert result.exit_code == 0, result.output
    assert (
        "clocks      trajectory header stamps 0.000 s behind the log time; 1 LiDAR(s) on "
        "another clock\n"
        "  lidar_front  header stamps 10368000.000 s behind the log time: shifted by "
        "+10368000.000 s onto the trajectory's clock\n"
    ) in result.stdout
    assert "    1     1.40 -    1.80 s    0.40 s            3           3\n" in result.stdout
    assert "- short stops: 2 of 2 stops last under 1 s" in result.stdout
    assert "- sparse stops: LiDAR lidar_front" in result.stdout
    assert "- clocks disagree: /lidar_front/points's header stamps" in result.stdout


def test_config_file_supplies_extrinsics(tmp_path: Path) -> None:
    config = tmp_path / "reader.yaml"
    config.write_text(
        "reader:\n  extrinsics:\n"
        "    lidar_front: {translation: [1, 2, 3]}\n"
        "    lidar_rear: {translation: [4, 5, 6], rotation_xyzw: [0, 0, 1, 0]}\n"
    )

    result = run(str(_recording(tmp_path, tf_static=False)), "--json", "--config", str(config))

    assert result.exit_code == 0, result.output
    lidars = json.loads(result.stdout)["lidars"]
    assert [lidar["initial_source"] for lidar in lidars] == ["config", "config"]
    assert lidars[1]["initial"]["translation"] == [4.0, 5.0, 6.0]


def test_bad_recording_exits_2_with_the_message(tmp_path: Path) -> None:
    junk = tmp_path / "upload.bag"
    junk.write_bytes(b"\x00" * 1000)

    result = run(str(junk), "--json")

    assert result.exit_code == 2
    assert result.stdout == ""
    assert result.stderr.startswith("error: ") and "not a recording we can read" in result.stderr
    assert "Traceback" not in result.output


def test_recording_error_exits_2(tmp_path: Path) -> None:
    result = run(str(_recording(tmp_path, trajectory="none")))
    assert result.exit_code == 2
    assert "error: " in result.stderr and "has no trajectory" in result.stderr


def test_bad_config_exits_2(tmp_path: Path) -> None:
    config = tmp_path / "reader.yaml"
    config.write_text("stops: {min_dwell_s: -1}\n")

    result = run(str(_recording(tmp_path)), "--config", str(config))

    assert result.exit_code == 2
    assert (
        "invalid reader config: stops.min_dwell_s: Input should be greater than 0" in result.stderr
    )


def test_options_override_config(tmp_path: Path) -> None:
    result = run(str(_recording(tmp_path)), "--odometry-topic", "/wheels")
    assert result.exit_code == 2
    assert "no nav_msgs/Odometry on /wheels" in result.stderr
