"""Synthesised calibration problems shared by the stage tests, simulated once per test session.

Set 1 with boxes at 5 % of the Mid-70's rate (16 stops, two LiDARs): small enough for unit tests,
rich enough that every degree of freedom is determined. The floor-only scenario has no objects.
"""

from __future__ import annotations

from functools import cache

import numpy as np
from numpy.typing import NDArray

from pipeline.calibrate import CalibrationResult, calibrate, prepare
from pipeline.config import PipelineConfig
from pipeline.problem import CalibrationProblem
from pipeline.segmentation import Segmentation, SegmentationConfig, SurfaceModel
from pipeline.stages.segment import segment_all
from pipeline.stages.state import CalibrationState
from pipeline.synth import Truth, simulate_problem
from pipeline.transforms import invert

RATE = 0.05


@cache
def box_problem() -> tuple[CalibrationProblem, Truth]:
    return simulate_problem("set1-box", seed=1, rate_scale=RATE)


@cache
def dense_box_problem() -> tuple[CalibrationProblem, Truth]:
    """The box problem at twice `RATE`: dense enough for a verdict that passes (at `RATE` the
    object surfaces' two models move the rear LiDAR beyond the 5 mm tolerance, so the
    1-sigma does too)."""
    return simulate_problem("set1-box", seed=1, rate_scale=2 * RATE)


@cache
def floor_only_problem() -> tuple[CalibrationProblem, Truth]:
    return simulate_problem("floor-only", seed=0, rate_scale=RATE)


@cache
def box_prepared(
    surface_model: SurfaceModel | None = None,
) -> tuple[CalibrationState, tuple[tuple[Segmentation, ...], ...]]:
    """The box problem prepared and segmented with the default config (with `surface_model`'s
    surfaces where given)."""
    problem, _ = box_problem()
    config = PipelineConfig()
    if surface_model is not None:
        config = PipelineConfig(segmentation=SegmentationConfig(surface_model=surface_model))
    prepared = prepare(problem, config)
    return prepared, segment_all(prepared, config)


@cache
def box_calibration() -> CalibrationResult:
    return calibrate(box_problem()[0], PipelineConfig())


@cache
def dense_box_calibration() -> CalibrationResult:
    return calibrate(dense_box_problem()[0], PipelineConfig())


@cache
def floor_only_calibration() -> CalibrationResult:
    return calibrate(floor_only_problem()[0], PipelineConfig())


def true_T_ref_lidar(truth: Truth, frames: tuple[str, ...]) -> NDArray[np.float64]:
    """(L, 4, 4) true extrinsics relative to `frames[0]` (the reference)."""
    true = {lidar.frame: lidar.T_base_lidar_true for lidar in truth.lidars}
    return np.stack([invert(true[frames[0]]) @ true[frame] for frame in frames])


def true_T_G_ref(truth: Truth, reference: str) -> NDArray[np.float64]:
    """(J, 4, 4) true poses of the reference per stop in G (the reference at stop 0)."""
    T_base_ref = {lidar.frame: lidar.T_base_lidar_true for lidar in truth.lidars}[reference]
    T_odom_G = truth.stops[0].T_odom_base_true @ T_base_ref
    return np.stack([invert(T_odom_G) @ stop.T_odom_base_true @ T_base_ref for stop in truth.stops])
