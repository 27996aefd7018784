"""`fleetcal calibrate`: a written recording in, a schema-valid result.json and exit code out."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
import typer
from typer.testing import CliRunner, Result

from pipeline.cli import calibrate as calibrate_cli
from pipeline.result import result_schema
from pipeline.synth.recording import write_recording

app = typer.Typer()
calibrate_cli.register(app)
app.command("noop", hidden=True)(lambda: None)  # keeps `calibrate` a named sub-command


def run(*args: str) -> Result:
    return CliRunner().invoke(app, ["calibrate", *args])


@pytest.fixture(scope="module")
def box_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Set 1 with boxes at 10 % of the Mid-70 rate: every degree of freedom determined, and
    dense enough that the surfaces' two models agree (at 5 % they move the rear LiDAR by more
    than the 5 mm tolerance, and the verdict fails on its 1-sigma)."""
    directory = tmp_path_factory.mktemp("box")
    write_recording("set1-box", directory, seed=1, rate_scale=0.1)
    return directory / "recording"


def test_a_good_recording_passes_with_exit_0(box_recording: Path, tmp_path: Path) -> None:
    output = tmp_path / "result.json"
    result = run(str(box_recording), "--output", str(output))
    assert result.exit_code == 0, result.output
    document = json.loads(output.read_text())
    jsonschema.Draft202012Validator(result_schema()).validate(document)
    assert document["verdict"]["passed"] is True
    assert "read" in document["stages"]
    assert "verdict: PASSED" in result.stdout
    assert "lidar_rear" in result.stdout and "metric error (eq. 12)" in result.stdout
    assert "off the surfaces the reference saw (seen metric): lidar_rear " in result.stdout
    for stage in ("read:", "segmentation:", "optimisation:", "verdict:"):
        assert stage in result.stderr


def test_a_failed_verdict_exits_1_and_names_the_failed_checks(
    box_recording: Path, tmp_path: Path
) -> None:
    config = tmp_path / "strict.yaml"
    config.write_text("verdict:\n  max_metric_error_m: 0.0001\n")
    output = tmp_path / "result.json"
    result = run(
        str(box_recording), "-o", str(output), "--config", str(config), "--reference", "lidar_rear"
    )
    assert result.exit_code == 1, result.output
    document = json.loads(output.read_text())
    assert document["reference_frame"] == "lidar_rear"
    assert document["config"]["verdict"]["max_metric_error_m"] == 0.0001
    assert "verdict: FAILED" in result.stdout and "metric_error" in result.stdout


def test_config_frames_the_recording_lacks_are_warned_about(
    box_recording: Path, tmp_path: Path
) -> None:
    config = tmp_path / "config.yaml"
    config.write_text(
        "reader:\n  extrinsics:\n    lidar_top: {translation: [0.0, 0.0, 1.0]}\n"
        "denoise:\n  scan_patterns:\n    lidar_top: repetitive\n"
        "  optical_axes:\n    lidar_side: [0.0, 1.0, 0.0]\n"
    )
    output = tmp_path / "result.json"
    result = run(str(box_recording), "-o", str(output), "--config", str(config))
    assert result.exit_code == 0, result.output
    warnings = json.loads(output.read_text())["warnings"]
    for setting, frame in [("scan_patterns", "lidar_top"), ("optical_axes", "lidar_side")]:
        [warning] = [w for w in warnings if f"denoise.{setting}" in w]
        assert f"names {frame!r}" in warning
        assert "(its LiDAR frames: lidar_front, lidar_rear)" in warning
        assert f"warning: {warning}" in result.stderr
    # The reader's own check of reader.extrinsics reaches the result and the output too.
    [reader_warning] = [w for w in warnings if "extrinsics for 'lidar_top'" in w]
    assert f"warning: {reader_warning}" in result.stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--reference", "lidar_top"], "reference LiDAR 'lidar_top' is not in the recording"),
        (["--config", "{missing}"], "cannot read config file"),
    ],
)
def test_bad_input_exits_2_without_traceback(
    box_recording: Path, tmp_path: Path, args: list[str], message: str
) -> None:
    args = [a.replace("{missing}", str(tmp_path / "absent.yaml")) for a in args]
    result = run(str(box_recording), "-o", str(tmp_path / "r.json"), *args)
    assert result.exit_code == 2
    assert message in result.stderr
    assert "Traceback" not in result.output
    assert not (tmp_path / "r.json").exists()


def test_a_file_that_is_not_a_recording_exits_2(tmp_path: Path) -> None:
    bogus = tmp_path / "notes.mcap"
    bogus.write_text("not a bag")
    result = run(str(bogus), "-o", str(tmp_path / "r.json"))
    assert result.exit_code == 2
    assert result.stderr.startswith("error: ")


@pytest.mark.parametrize(
    ("target", "message"),
    [
        (
            "missing/result.json",
            "cannot write {target}: No such file or directory; choose a writable path",
        ),
        (".", "cannot write {target}: it is a directory; name a file, e.g. {target}/result.json"),
    ],
)
def test_an_unwritable_output_exits_2_before_the_recording_is_read(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, target: str, message: str
) -> None:
    def never(*args: object, **kwargs: object) -> None:
        raise AssertionError("the recording was read before the output was checked")

    monkeypatch.setattr("pipeline.io.read_recording", never)
    path = tmp_path / target
    result = run(str(tmp_path / "absent.mcap"), "-o", str(path))
    assert result.exit_code == 2
    assert result.stderr == f"error: {message.format(target=path)}\n"


def test_the_output_check_leaves_no_file_and_keeps_an_existing_one(tmp_path: Path) -> None:
    from pipeline.cli.common import check_writable

    check_writable(tmp_path / "new.json")
    assert not (tmp_path / "new.json").exists()
    (tmp_path / "old.json").write_text("kept")
    check_writable(tmp_path / "old.json")
    assert (tmp_path / "old.json").read_text() == "kept"
