"""`calibrate(problem, config)`: the declared stages in order (`pipeline.stages.sequence`), from
noise filter to verdict, and the `CalibrationResult` they come to.

Frames: G is the reference LiDAR's frame at stop 0 (`T_G_ref[0]` = identity, the gauge); the
unknowns are the reference's pose per stop `T_G_ref` and the extrinsics relative to it
`T_ref_lidar`; reported extrinsics are `T_base_lidar = T_base_ref @ T_ref_lidar`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.config import PipelineConfig, config_hash, unknown_frame_warnings
from pipeline.optimisation import OptimisationResult
from pipeline.problem import CalibrationProblem
from pipeline.rough_refinement import RoughRefinementResult
from pipeline.runtime import tune_allocator
from pipeline.stages import denoise_stage
from pipeline.stages.runner import IterationProgress, Listeners, Progress, run_stages
from pipeline.stages.sequence import STAGE_SEQUENCE, STAGES
from pipeline.stages.setup import initial_state
from pipeline.stages.state import CalibrationState, LidarCalibration, StageReport, required
from pipeline.transforms import invert
from pipeline.verdict import Verdict

__all__ = [
    "STAGES",
    "CalibrationResult",
    "IterationProgress",
    "LidarCalibration",
    "Progress",
    "StageReport",
    "calibrate",
    "prepare",
]


@dataclass(frozen=True)
class CalibrationResult:
    """Everything `result.json` reports, plus the stage results for benchmarks.

    `lidars` has the reference first, then the others in sorted order. `T_odom_base` (J, 4, 4):
    the refined stop poses of the base in the odometry frame. `error_per_iteration`: eq. 11 of
    stage 4 per iteration (metres). `object_distances_final_m`: per LiDAR (reference first,
    empty), each object point's distance to the reference's map after calibration, capped as
    eq. 12 caps it (what `metric_error_final` averages). `warnings`: what the user should fix or
    know, the recording's (`recording.warnings`) and the config's settings that name LiDAR frames
    it does not have.
    """

    reference_frame: str
    base_frame: str
    lidars: tuple[LidarCalibration, ...]
    metric_error_initial: float
    metric_error_final: float
    verdict: Verdict
    stages: Mapping[str, StageReport]
    converged: bool
    iterations: int
    error_per_iteration: tuple[float, ...]
    T_odom_base: NDArray[np.float64]
    config: PipelineConfig
    config_hash: str
    pipeline_version: str
    optimisation: OptimisationResult
    rough_refinement: RoughRefinementResult | None
    object_distances_final_m: tuple[NDArray[np.float64], ...] = ()
    warnings: tuple[str, ...] = ()

    @property
    def passed(self) -> bool:
        return self.verdict.passed

    def lidar(self, frame: str) -> LidarCalibration:
        for lidar in self.lidars:
            if lidar.frame == frame:
                return lidar
        raise KeyError(f"no LiDAR {frame!r}; calibrated: {[x.frame for x in self.lidars]}")

    def T_base_lidar_per_iteration(self, frame: str) -> NDArray[np.float64]:
        """(K + 1, 4, 4): this LiDAR's `T_base_lidar` before each stage-4 step and at the end
        (the reference's `T_base_ref` as calibrated)."""
        index = [x.frame for x in self.lidars].index(frame)
        T_base_ref = self.lidars[0].T_base_lidar_calibrated
        history: NDArray[np.float64] = (
            T_base_ref @ self.optimisation.T_ref_lidar_per_iteration[:, index]
        )
        return history


def prepare(problem: CalibrationProblem, config: PipelineConfig) -> CalibrationState:
    """The state as stage 1 leaves it: LiDARs ordered, floors fitted, clouds filtered (the set-up
    the baselines share with the proposed method)."""
    return denoise_stage.run(initial_state(problem, config.frames), config, Listeners()).state


def calibrate(
    problem: CalibrationProblem,
    config: PipelineConfig | None = None,
    progress: Progress | None = None,
    on_iteration: IterationProgress | None = None,
) -> CalibrationResult:
    """Calibrate every LiDAR of `problem` relative to the reference; see `CalibrationResult`.

    Raises `BadInputError` when the problem cannot be calibrated at all (fewer than two LiDARs
    or stops, an unknown reference, no floor anywhere). Data that are merely poor (no objects,
    no convergence) give a result whose verdict fails, with the failed checks named.
    `progress` hears of each stage as it ends, `on_iteration` of each optimisation iteration.
    """
    config = config or PipelineConfig()
    tune_allocator()
    state, stages = run_stages(
        initial_state(problem, config.frames),
        config,
        STAGE_SEQUENCE,
        Listeners(progress=progress, on_iteration=on_iteration),
    )
    return _result(problem, config, state, stages)


def _result(
    problem: CalibrationProblem,
    config: PipelineConfig,
    state: CalibrationState,
    stages: Mapping[str, StageReport],
) -> CalibrationResult:
    """The stages' final state as a result, the stop poses back in the odometry frame."""
    from pipeline import __version__

    optimised = required(state.optimised, "optimisation")
    T_odom_G = problem.stops[0].T_odom_base @ state.T_base_ref_initial
    T_ref_base = invert(state.T_base_ref_initial)
    return CalibrationResult(
        reference_frame=state.lidars[0].frame,
        base_frame=problem.base_frame,
        lidars=required(state.calibrations, "verdict"),
        metric_error_initial=required(state.metric_initial, "metric").value,
        metric_error_final=required(state.metric_final, "metric").value,
        object_distances_final_m=required(state.metric_final, "metric").capped,
        verdict=required(state.verdict, "verdict"),
        stages=stages,
        converged=optimised.converged,
        iterations=optimised.iterations,
        error_per_iteration=optimised.error_per_iteration,
        T_odom_base=np.stack([T_odom_G @ T @ T_ref_base for T in state.T_G_ref]),
        config=config,
        config_hash=config_hash(config),
        pipeline_version=__version__,
        optimisation=optimised,
        rough_refinement=state.floor_refinement,
        warnings=(
            *(problem.recording.warnings if problem.recording is not None else ()),
            *unknown_frame_warnings(config, problem.frames),
        ),
    )
