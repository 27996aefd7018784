"""The moving-points stage on a synthesised stop sequence with two people walking by: what it
removes is, almost all of it, what the synthesiser labels as on a walker, and it says how much
per LiDAR; a world without walkers loses nothing."""

from __future__ import annotations

import dataclasses
from typing import cast

import numpy as np
import pytest

from pipeline.config import PipelineConfig
from pipeline.stages import moving
from pipeline.stages.runner import Listeners
from pipeline.stages.setup import initial_state
from pipeline.synth.simulate import simulate_problem

pytestmark = pytest.mark.slow


@pytest.mark.parametrize(("scenario", "walkers"), [("people", True), ("set1-box", False)])
def test_removed_points_are_the_walkers(scenario: str, walkers: bool) -> None:
    problem, truth = simulate_problem(scenario, seed=0, rate_scale=0.1)
    config = PipelineConfig()
    state = initial_state(problem, config.frames)
    outcome = moving.run(state, config, Listeners())
    # The stage's counts are numbers (its details may also hold flags and words).
    details = cast("dict[str, int]", outcome.details)
    removed = truth_moving = hits = 0
    for lidar, before, after, sizes in zip(
        state.lidars,
        state.clouds_in_lidar,
        outcome.state.clouds_in_lidar,
        outcome.state.scan_sizes,
        strict=True,
    ):
        for stop, (cloud, kept, kept_sizes) in enumerate(zip(before, after, sizes, strict=True)):
            labels = truth.stop_labels(stop, lidar.frame).is_moving
            assert len(labels) == len(cloud)
            assert sum(kept_sizes) == len(kept)
            # What is kept is a subset of the cloud in order: match it back by position.
            kept_rows = {row.tobytes() for row in kept}
            gone = np.array([row.tobytes() not in kept_rows for row in cloud], dtype=bool)
            removed += gone.sum()
            truth_moving += labels.sum()
            hits += (gone & labels).sum()
        assert details[f"removed_points.{lidar.frame}"] >= 0
    assert details["removed_points"] == removed
    if walkers:
        assert truth_moving > 0
        assert hits / removed > 0.9  # precision
        # Recall at this sparse rate (a tenth of a Mid-70's points): 0.15; 0.83 at 0.3 of the rate.
        # A rosette this sparse rarely returns twice from one direction in a stop, so few points
        # are seen through; slow walkers also look static to the second test.
        assert hits / truth_moving > 0.1
    else:
        assert removed == 0
    assert details["judged_clouds"] > 0


@pytest.mark.parametrize("enabled", [True, False])
def test_clouds_whose_scans_are_unknown_are_counted_as_not_judged(enabled: bool) -> None:
    """A recording that does not say which points came in which scan (empty `scan_sizes`, as
    `initial_state` makes them then) keeps every point; with the stage enabled each non-empty
    cloud is counted as not judged."""
    problem, _ = simulate_problem("set1-box", seed=0, rate_scale=0.05)
    config = PipelineConfig.model_validate({"moving_points": {"enabled": enabled}})
    known = initial_state(problem, config.frames)
    unknown = tuple(((),) * len(row) for row in known.clouds_in_lidar)
    state = dataclasses.replace(known, scan_sizes=unknown)
    outcome = moving.run(state, config, Listeners())
    non_empty = sum(len(cloud) > 0 for row in state.clouds_in_lidar for cloud in row)
    assert non_empty > 0
    assert outcome.details["skipped_clouds"] == (non_empty if enabled else 0)
    assert outcome.details["judged_clouds"] == outcome.details["removed_points"] == 0
    assert outcome.state.clouds_in_lidar == state.clouds_in_lidar


def test_the_thread_count_changes_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    problem, _ = simulate_problem("people", seed=0, rate_scale=0.1)
    config = PipelineConfig()
    state = initial_state(problem, config.frames)
    outcomes = []
    for threads in ("1", "3"):
        monkeypatch.setenv("OMP_NUM_THREADS", threads)
        outcomes.append(moving.run(state, config, Listeners()))
    one, three = outcomes
    assert one.details == three.details
    assert one.state.scan_sizes == three.state.scan_sizes
    for row_one, row_three in zip(
        one.state.clouds_in_lidar, three.state.clouds_in_lidar, strict=True
    ):
        assert all(np.array_equal(a, b) for a, b in zip(row_one, row_three, strict=True))
