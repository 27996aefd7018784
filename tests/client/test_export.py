"""`fleetcal export` from a result.json: every text format round-trips to the result, the
calibrated recording reads back, and refusals exit 2 with a message."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import pytest
import typer
from typer.testing import CliRunner, Result

from client import export as export_cli
from pipeline.export import ExportFormat
from pipeline.io.writer import WriterFormat
from pipeline.transforms import to_translation_xyzw
from tests.pipeline.io.recordings import TRUE_EXTRINSICS, Spec, write_recording
from tests.pipeline.test_export import (
    PARSERS,
    assert_recording_has,
    assert_same,
    set1_document,
)

app = typer.Typer()
export_cli.register(app)
app.command("noop", hidden=True)(lambda: None)  # keeps `export` a named sub-command


def run(*args: str) -> Result:
    return CliRunner().invoke(app, ["export", *args], env={"FLEETCAL_API_KEY": ""})


@pytest.fixture
def result_json(tmp_path: Path) -> Path:
    path = tmp_path / "result.json"
    path.write_text(json.dumps(set1_document()))
    return path


@pytest.mark.parametrize("fmt", list(PARSERS))
def test_text_formats_to_stdout_round_trip(result_json: Path, fmt: ExportFormat) -> None:
    result = run(str(result_json), "--format", fmt)
    assert result.exit_code == 0, result.output
    assert_same(PARSERS[fmt](result.stdout), set1_document())


def test_out_writes_a_file_and_a_run_document_is_accepted(tmp_path: Path) -> None:
    saved = tmp_path / "run.json"
    saved.write_text(json.dumps({"id": "x", "status": "succeeded", "result": set1_document()}))
    out = tmp_path / "robot.urdf"
    result = run(str(saved), "-f", "urdf", "-o", str(out))
    assert result.exit_code == 0, result.output
    assert_same(PARSERS[ExportFormat.URDF](out.read_text()), set1_document())
    assert f"source: {saved}" in out.read_text()


def true_document() -> dict[str, Any]:
    """A result whose calibrated extrinsics are those `write_recording` records as true."""
    document = set1_document()
    document["lidars"] = {
        frame: {
            "topic": f"/{frame}/points",
            "calibrated": {"translation": t.tolist(), "rotation_xyzw": q.tolist()},
        }
        for frame, (t, q) in ((f, to_translation_xyzw(T)) for f, T in TRUE_EXTRINSICS.items())
    }
    return document


def test_the_calibrated_recording_reads_back(tmp_path: Path) -> None:
    recording = tmp_path / "rec"
    write_recording(recording, WriterFormat.ROS2_MCAP, Spec(stops=2, points=60))
    document = true_document()
    result_json = tmp_path / "result.json"
    result_json.write_text(json.dumps(document))
    out = tmp_path / "calibrated"
    result = run(str(result_json), "-f", "recording", "--recording", str(recording), "-o", str(out))
    assert result.exit_code == 0, result.output
    assert "base_link->rear_mount" in result.output
    assert_recording_has(out, document)


def test_a_recording_of_other_lidars_is_refused_unless_forced(tmp_path: Path) -> None:
    other = tmp_path / "other-robot"
    write_recording(other, WriterFormat.ROS2_MCAP, Spec(stops=2, points=60, frame_prefix="r2_"))
    result_json = tmp_path / "result.json"
    result_json.write_text(json.dumps(true_document()))
    out = tmp_path / "calibrated"
    args = [str(result_json), "-f", "recording", "--recording", str(other), "-o", str(out)]

    refused = run(*args)
    assert refused.exit_code == 2, refused.output
    assert f"{other} is not the recording this result calibrated: it has no LiDAR " in (
        refused.stderr
    )
    assert "lidar_front, lidar_rear (its LiDARs: r2_lidar_front on " in refused.stderr
    assert "--force" in refused.stderr and not out.exists()

    forced = run(*args, "--force")
    assert forced.exit_code == 0, forced.output
    assert f"warning: {other}: it has no LiDAR lidar_front, lidar_rear" in forced.stderr
    assert "r2_lidar_front, r2_lidar_rear: not in the result, kept with the recorded" in (
        forced.stderr
    )
    assert out.exists()


def test_a_run_documents_upload_must_be_the_recording(tmp_path: Path) -> None:
    recording = tmp_path / "rec.bag"
    write_recording(recording, WriterFormat.ROS1, Spec(stops=2, points=60))
    sha256 = hashlib.sha256(recording.read_bytes()).hexdigest()
    saved = tmp_path / "run.json"

    def export(upload_sha256: str, out: Path) -> Result:
        run_document = {"status": "succeeded", "upload": {"sha256": upload_sha256}}
        saved.write_text(json.dumps(run_document | {"result": true_document()}))
        return run(str(saved), "-f", "recording", "--recording", str(recording), "-o", str(out))

    other = "ab" * 32
    refused = export(other, tmp_path / "refused.bag")
    assert refused.exit_code == 2, refused.output
    assert f"its SHA-256 is {sha256}, the calibrated upload's {other}" in refused.stderr
    assert not (tmp_path / "refused.bag").exists()

    written = export(sha256.upper(), tmp_path / "written.bag")
    assert written.exit_code == 0, written.output
    assert "warning" not in written.stderr
    assert_recording_has(tmp_path / "written.bag", true_document())


def test_a_failed_verdict_exits_2_unless_allowed(tmp_path: Path) -> None:
    document = set1_document()
    document["verdict"] = {"passed": False, "checks": [{"name": "convergence", "passed": False}]}
    path = tmp_path / "result.json"
    path.write_text(json.dumps(document))
    refused = run(str(path), "-f", "extrinsics")
    assert refused.exit_code == 2
    assert "did not pass its verdict (failed checks: convergence)" in refused.output
    assert run(str(path), "-f", "extrinsics", "--allow-failed").exit_code == 0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["nothing-here.json", "-f", "urdf"], "neither a file nor a run id"),
        (["{json}", "-f", "recording"], "needs --out PATH"),
        (["{json}", "-f", "recording", "-o", "{json}"], "already exists"),
        (["{json}", "-f", "recording", "-o", "{tmp}/new"], "needs --recording PATH"),
        (["{bad}", "-f", "urdf"], "cannot read"),
        (["{unfinished}", "-f", "urdf"], "the run is running and has no result yet"),
        (["0f0e4d1a-0000-4000-8000-000000000000", "-f", "urdf"], "needs an API key"),
    ],
)
def test_bad_invocations_exit_2_with_a_message(
    tmp_path: Path, result_json: Path, args: list[str], message: str
) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    unfinished = tmp_path / "unfinished.json"
    unfinished.write_text(json.dumps({"id": "x", "status": "running", "result": None}))
    names = {"json": result_json, "tmp": tmp_path, "bad": bad, "unfinished": unfinished}
    result = run(*(arg.format(**names) for arg in args))
    assert result.exit_code == 2, result.output
    assert message in result.output


def test_an_unreachable_service_is_named(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        app,
        [
            "export",
            "0f0e4d1a-0000-4000-8000-000000000000",
            "-f",
            "urdf",
            "--url",
            "http://127.0.0.1:9",
            "--api-key",
            "fck_x",
        ],
    )
    assert result.exit_code == 2
    assert "cannot reach the fleetcal service at http://127.0.0.1:9" in result.output
