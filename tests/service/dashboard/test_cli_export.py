"""`fleetcal export RUN_ID` against the running service: text formats from the run's result and
the calibrated recording made by the service, both back to the result's transforms."""

from __future__ import annotations

from pathlib import Path

import typer
from typer.testing import CliRunner, Result

from client import export as export_cli
from pipeline.export import ExportFormat
from tests.pipeline.test_export import PARSERS, assert_recording_has, assert_same
from tests.service.dashboard.conftest import LiveApp

app = typer.Typer()
export_cli.register(app)
app.command("noop", hidden=True)(lambda: None)


def export(live_app: LiveApp, *args: str) -> Result:
    return CliRunner().invoke(
        app,
        ["export", *args, "--url", live_app.url],
        env={"FLEETCAL_API_KEY": live_app.read_key},
    )


def test_a_run_id_exports_its_result(live_app: LiveApp) -> None:
    run = live_app.fleet.repaired
    result = export(live_app, str(run), "--format", "tf-static")
    assert result.exit_code == 0, result.output
    assert f"# source: run {run}" in result.stdout
    assert_same(PARSERS[ExportFormat.TF_STATIC](result.stdout), live_app.fleet.documents[run])


def test_a_run_id_downloads_the_calibrated_recording(live_app: LiveApp, tmp_path: Path) -> None:
    run = live_app.fleet.repaired
    out = tmp_path / "calibrated.mcap"
    result = export(live_app, str(run), "-f", "recording", "-o", str(out))
    assert result.exit_code == 0, result.output
    assert_recording_has(out, live_app.fleet.documents[run])
    assert not list(tmp_path.glob("*.part"))


def test_the_service_refusal_is_shown(live_app: LiveApp, tmp_path: Path) -> None:
    result = export(live_app, str(live_app.fleet.hit), "-f", "recording", "-o", str(tmp_path / "x"))
    assert result.exit_code == 2
    assert "409" in result.output and "did not pass its verdict" in result.output
    assert not (tmp_path / "x").exists() and not list(tmp_path.glob("*.part"))
    unfinished = export(live_app, str(live_app.fleet.running), "-f", "urdf")
    assert unfinished.exit_code == 2
    assert "the run is running and has no result yet" in unfinished.output


def test_a_wrong_key_is_named(live_app: LiveApp) -> None:
    result = CliRunner().invoke(
        app,
        ["export", str(live_app.fleet.repaired), "-f", "urdf", "--url", live_app.url],
        env={"FLEETCAL_API_KEY": "fck_000000000000_" + "x" * 43},
    )
    assert result.exit_code == 2
    assert "401" in result.output and "unknown or revoked" in result.output
