"""Scan patterns from PointCloud2 fields and, without a beam field, from the directions fired:
the synthesiser's LiDAR models, dense and sparse, with exact and free-running azimuths."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from pipeline.io.scan_pattern import DirectionRecurrence, pattern_from_fields
from pipeline.problem import ScanPattern
from pipeline.synth.lidar_models import LidarModel, Mid70, SpinningLidar

# 360 / 0.2317 is no whole number of columns: each turn fires at new azimuths (free-running).
FREE_RUNNING = SpinningLidar(azimuth_resolution_deg=0.2317)


def model_scans(
    model: LidarModel,
    scans: int = 12,
    *,
    rate_scale: float = 1.0,
    returns: float = 1.0,
    seed: int = 0,
) -> list[NDArray[np.float64]]:
    """Consecutive scans of `model` at random ranges; `returns`: the fraction that come back."""
    rng = np.random.default_rng(seed)
    clouds = []
    for k in range(scans):
        firing = model.firing(3.0 + k * model.scan_period_s, model.scan_period_s, rate_scale)
        directions = firing.directions[rng.random(len(firing)) < returns]
        clouds.append(directions * rng.uniform(1.0, 10.0, (len(directions), 1)))
    return clouds


def judged(clouds: list[NDArray[np.float64]]) -> tuple[ScanPattern, float | None]:
    recurrence = DirectionRecurrence()
    for cloud in clouds:
        recurrence.add(cloud)
    judgement = recurrence.judge()
    return judgement.pattern, judgement.recurrence


@pytest.mark.parametrize(
    ("fields", "expected"),
    [
        (("x", "y", "z", "intensity", "ring", "time"), ScanPattern.REPETITIVE),  # velodyne
        (("x", "y", "z", "intensity", "return_type", "channel"), ScanPattern.REPETITIVE),  # nebula
        (("x", "y", "z", "intensity", "laser_id"), ScanPattern.REPETITIVE),  # Luminar
        (("x", "y", "z", "intensity", "tag", "line", "timestamp"), ScanPattern.NON_REPETITIVE),
        (("x", "y", "z", "intensity", "line"), ScanPattern.NON_REPETITIVE),
    ],
)
def test_beam_fields_tell_the_pattern(fields: tuple[str, ...], expected: ScanPattern) -> None:
    judgement = pattern_from_fields(fields)
    assert judgement is not None and judgement.pattern is expected


def test_fields_without_a_beam_index_tell_nothing() -> None:
    assert pattern_from_fields(("x", "y", "z", "intensity")) is None


@pytest.mark.parametrize(
    ("name", "model", "rate_scale", "returns"),
    [
        ("16 beams", SpinningLidar(), 1.0, 1.0),
        ("free-running azimuths", FREE_RUNNING, 1.0, 1.0),
        ("64 beams, half the returns", SpinningLidar(beams=64, elevation_deg=(-25, 15)), 1.0, 0.5),
        ("front half only, quarter rate", SpinningLidar(azimuth_mask_deg=(-90, 90)), 0.25, 1.0),
        ("sparse: 750 points a scan", FREE_RUNNING, 0.1, 0.3),
    ],
)
def test_spinning_lidars_are_repetitive(
    name: str, model: LidarModel, rate_scale: float, returns: float
) -> None:
    pattern, recurrence = judged(model_scans(model, rate_scale=rate_scale, returns=returns))
    assert pattern is ScanPattern.REPETITIVE, f"{name}: recurrence {recurrence}"


@pytest.mark.parametrize(
    ("rate_scale", "returns"),
    [(1.0, 1.0), (0.1, 1.0), (0.02, 1.0), (0.1, 0.3)],  # 10,000 down to 200-300 points a scan
)
def test_rosettes_are_non_repetitive(rate_scale: float, returns: float) -> None:
    pattern, recurrence = judged(model_scans(Mid70(), rate_scale=rate_scale, returns=returns))
    assert pattern is ScanPattern.NON_REPETITIVE, f"recurrence {recurrence}"


def test_a_moving_base_changes_which_directions_return_not_the_pattern() -> None:
    """Only the rays that meet the floor return, and the floor tilts and drops scan after scan
    under the LiDAR (in its own frame): a spinning LiDAR stays repetitive."""
    clouds = []
    for k, directions in enumerate(
        d / np.linalg.norm(d, axis=1)[:, None] for d in model_scans(FREE_RUNNING)
    ):
        tilt, height = np.radians(3.0 * k), 0.5 + 0.05 * k
        down = np.array([np.sin(tilt), 0.0, -np.cos(tilt)])
        toward_floor = directions @ down
        hit = toward_floor > 0.05
        clouds.append(directions[hit] * (height / toward_floor[hit])[:, None])
    assert judged(clouds)[0] is ScanPattern.REPETITIVE


def test_too_few_scans_leave_the_pattern_unknown() -> None:
    recurrence = DirectionRecurrence()
    for cloud in model_scans(SpinningLidar(), scans=3):
        recurrence.add(cloud)
    judgement = recurrence.judge()
    assert judgement.pattern is ScanPattern.UNKNOWN
    assert "only 3 scans" in judgement.basis


def test_scans_too_sparse_to_judge_leave_it_unknown_and_stop_asking() -> None:
    recurrence = DirectionRecurrence()
    while recurrence.wants_more:  # a LiDAR that sees 50 points a scan is not decoded forever
        recurrence.add(np.random.default_rng(recurrence.skipped).normal(size=(50, 3)))
    judgement = recurrence.judge()
    assert judgement.pattern is ScanPattern.UNKNOWN
    assert recurrence.skipped == 100 and "100 sparser ones" in judgement.basis


def test_a_recurrence_in_between_is_unknown() -> None:
    """A twentieth of the rate, 30 % returns: 350 points a scan on 16 beams, too sparse to tell."""
    pattern, recurrence = judged(model_scans(FREE_RUNNING, rate_scale=0.05, returns=0.3))
    assert pattern is ScanPattern.UNKNOWN and recurrence is not None
    assert 0.5 <= recurrence <= 0.8
