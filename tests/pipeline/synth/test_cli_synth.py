"""`fleetcal synth`: writes a recording, exits 2 with a clear message on bad input."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from pipeline.io import read_recording
from pipeline.synth import load_truth
from pipeline.synth.random_scenario import random_scenario
from pipeline.synth.scenarios import ScenarioSpec
from pipeline.transforms import pose_difference
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


# Synced clocks, stops of 1.1 s or more and seven stops: the reader as it stands accepts it.
READABLE_SEED = 261


def test_synth_random_writes_a_readable_recording_whose_truth_holds_every_factor(
    tmp_path: Path,
) -> None:
    out = tmp_path / "random"
    result = runner.invoke(
        app,
        [
            "synth",
            "random",
            "--seed",
            str(READABLE_SEED),
            "--out",
            str(out),
            "--rate-scale",
            "0.01",
        ],
    )
    assert result.exit_code == 0, result.output
    spec = random_scenario(READABLE_SEED)
    assert f"class {spec.scenario_class}" in result.stderr
    doc = json.loads((out / "truth.json").read_text())
    assert ScenarioSpec.model_validate(doc["spec"]) == spec
    assert doc["scenario_class"] == spec.scenario_class and doc["scenario"] == spec.name
    assert set(doc["lidars"]) == {m.frame for m in spec.lidars}
    assert len(doc["objects"]) == len(spec.scene.objects) and len(doc["stops"]) == spec.motion.stops
    assert all("perturbation" in stop for stop in doc["stops"])
    for key in ("odometry_error", "odometry_drift", "extrinsic_error", "header_clock_offset_ns"):
        assert key in doc["spec"]
    truth = load_truth(out)
    problem = read_recording(out / "recording")
    assert problem.frames == tuple(sorted(m.frame for m in spec.lidars))
    assert len(problem.stops) == spec.motion.stops
    for lidar in problem.lidars:
        translation, rotation = pose_difference(
            lidar.T_base_lidar, truth.lidar(lidar.frame).T_base_lidar_initial
        )
        assert translation < 1e-6 and rotation < 1e-4


def test_synth_random_with_a_negative_seed_exits_2(tmp_path: Path) -> None:
    result = runner.invoke(app, ["synth", "random", "--seed", "-3", "--out", str(tmp_path / "x")])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert not (tmp_path / "x").exists()


def test_synth_world_is_for_random_only_and_an_unknown_one_is_named(tmp_path: Path) -> None:
    result = runner.invoke(app, ["synth", "tiny", "--world", "room", "--out", str(tmp_path / "x")])
    assert result.exit_code == 2 and "--world is for `fleetcal synth random`" in result.stderr
    result = runner.invoke(
        app, ["synth", "random", "--world", "warehouse", "--out", str(tmp_path / "x")]
    )
    assert result.exit_code == 2 and "unknown world 'warehouse'" in result.stderr
    assert not (tmp_path / "x").exists()
