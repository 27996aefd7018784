"""`fleetcal synth`: writes a recording, exits 2 with a clear message on bad input."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from workers.cli import app

runner = CliRunner()


def test_synth_writes_a_recording(tmp_path: Path) -> None:
    out = tmp_path / "tiny"
    result = runner.invoke(
        app, ["synth", "tiny", "--out", str(out), "--seed", "3", "--rate-scale", "0.5"]
    )
    assert result.exit_code == 0, result.output
    assert (out / "recording" / "metadata.yaml").is_file() and (out / "truth.json").is_file()
    assert not (out / "recording.bag").exists()
    assert "tiny: stop 4/4" in result.stderr


def test_unknown_scenario_exits_2_listing_the_known_ones(tmp_path: Path) -> None:
    result = runner.invoke(app, ["synth", "warehouse", "--out", str(tmp_path / "x")])
    assert result.exit_code == 2
    assert "unknown scenario 'warehouse'; choose one of:" in result.stderr
    assert "set1-box" in result.stderr and "Traceback" not in result.output
    assert not (tmp_path / "x").exists()


def test_existing_output_exits_2(tmp_path: Path) -> None:
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "file").write_text("x")
    result = runner.invoke(app, ["synth", "tiny", "--out", str(tmp_path / "taken")])
    assert result.exit_code == 2
    assert "already exists and is not empty" in result.stderr
