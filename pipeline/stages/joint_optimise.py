"""Stage 4, the optimisation: every LiDAR's object points against the reference's, with the
floor terms when stage 3 gave a floor (`pipeline.optimisation`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from functools import partial
from typing import TypedDict

import numpy as np
from numpy.typing import NDArray

from pipeline.config import PipelineConfig
from pipeline.geometry import Plane
from pipeline.metric import (
    MetricError,
    SolutionComparison,
    capped_distances,
    compare_solutions,
    metric_of,
)
from pipeline.optimisation import OptimisationResult, optimise
from pipeline.optimisation.config import FALLBACK_FLOOR_SIGMA, OptimisationConfig
from pipeline.optimisation.solver import evaluate_at
from pipeline.stages.runner import IterationProgress, Listeners, StageOutcome
from pipeline.stages.state import CalibrationState, Detail, required
from pipeline.transforms import Points


def _iteration_of(
    on_iteration: IterationProgress, done_before: int, max_iterations: int, iteration: int
) -> None:
    on_iteration(done_before + iteration, max_iterations)


def run(state: CalibrationState, config: PipelineConfig, listeners: Listeners) -> StageOutcome:
    """Refine `T_G_ref` and `T_ref_lidar` on the objects; `listeners.on_iteration` hears of
    every iteration. With a second start (global alignment's candidate) the optimisation runs
    from both and keeps the solution whose non-reference points lie nearer the reference's map
    (the metric error, eq. 12: distances capped, so surfaces the reference never saw weigh
    alike in both), and compares the two point by point: where they end apart and the maps
    cannot tell them apart, the verdict says the data are ambiguous (`SolutionComparison`).
    Iterations are counted on over the two runs, so progress never goes back."""
    starts = 1 if state.second_start is None else 2
    result = optimise_from(state, config, listeners, (state.T_G_ref, state.T_ref_lidar), starts)
    details: dict[str, Detail] = {}
    kept_metric: MetricError | None = None
    comparison: SolutionComparison | None = None
    if state.second_start is not None:
        other = optimise_from(
            state, config, listeners, state.second_start, starts, done_before=result.iterations
        )
        objects = state.objects_in_lidar()
        # Measured once per solution: eq. 12 chooses between them, the comparison reuses it.
        first_distances, second_distances = (
            capped_distances(objects, x.T_G_ref, x.T_ref_lidar, config.metric)
            for x in (result, other)
        )
        first, second = metric_of(first_distances), metric_of(second_distances)
        second_kept = second.value < first.value
        details.update(
            starts=2,
            metric_error_m=first.value,
            second_start_metric_error_m=second.value,
            second_start_kept=second_kept,
            iterations_all_starts=result.iterations + other.iterations,
        )
        kept, dropped = (other, result) if second_kept else (result, other)
        kept_distances, dropped_distances = (
            (second_distances, first_distances)
            if second_kept
            else (first_distances, second_distances)
        )
        comparison = compare_solutions(
            kept_distances,
            dropped_distances,
            kept.T_ref_lidar,
            dropped.T_ref_lidar,
            config.optimisation.uncertainty_block_m,
        )
        details.update(
            starts_apart_m=comparison.apart_translation_m,
            starts_apart_deg=comparison.apart_rotation_deg,
            kept_start_nearer_m=comparison.difference_m,
            kept_start_nearer_stderr_m=comparison.stderr_m,
        )
        result, kept_metric = kept, (second if second_kept else first)
    details.update(
        iterations=result.iterations,
        converged=result.converged,
        residual=config.optimisation.residual,
        residual_rms_m=result.residual_rms_m,
    )
    if config.optimisation.acceleration != "none":
        details["accelerated_steps"] = result.accelerated_steps
    new_state = dataclasses.replace(
        state,
        optimised=result,
        T_G_ref=result.T_G_ref,
        T_ref_lidar=result.T_ref_lidar,
        # The metric stage reuses what the choice between two starts measured.
        metric_final=kept_metric,
        start_comparison=comparison,
    )
    message = (
        f"{result.iterations} iterations, {'converged' if result.converged else 'NOT converged'}"
    )
    if details.get("second_start_kept"):
        message += " (from global alignment's candidate, nearer the reference's map)"
    return StageOutcome(new_state, details, message)


def optimise_from(
    state: CalibrationState,
    config: PipelineConfig,
    listeners: Listeners,
    start: tuple[NDArray[np.float64], NDArray[np.float64]],
    starts: int,
    done_before: int = 0,
) -> OptimisationResult:
    """Stage 4 from `start` (`T_G_ref`, `T_ref_lidar`), one of `starts` runs; its iterations are
    reported after the `done_before` of the runs before it, out of `starts` times the limit."""
    on_iteration = listeners.on_iteration
    T_G_ref, T_ref_lidar = start
    max_iterations = starts * config.optimisation.max_iterations
    return optimise(
        state.objects_in_lidar(),
        T_G_ref,
        T_ref_lidar,
        stage4_config(state, config),
        **_floors_and_normals(state),
        on_iteration=None
        if on_iteration is None
        else partial(_iteration_of, on_iteration, done_before, max_iterations),
        range_bias=config.observability.range_bias == "estimated",
    )


def evaluate_solution(state: CalibrationState, config: PipelineConfig) -> OptimisationResult:
    """Stage 4's terms on `state`'s clouds at `state`'s poses, the robust kernel where stage 4
    left it (`optimisation.kernel_scale_m`), without a step: the same solution judged on clouds
    segmented otherwise."""
    optimised = required(state.optimised, "optimisation")
    return evaluate_at(
        state.objects_in_lidar(),
        state.T_G_ref,
        state.T_ref_lidar,
        stage4_config(state, config),
        kernel_scale_m=optimised.kernel_scale_m,
        **_floors_and_normals(state),
    )


def stage4_config(state: CalibrationState, config: PipelineConfig) -> OptimisationConfig:
    """`config.optimisation` with the floor terms' sigmas it leaves to be measured (None) taken
    from stage 3's floor residuals (`RoughRefinementResult.noise`), or `FALLBACK_FLOOR_SIGMA`
    where stage 3 did not run or left nothing to measure them by."""
    options = config.optimisation
    noise = state.floor_refinement.noise if state.floor_refinement is not None else None
    tilt_deg, offset_m = (
        (noise.tilt_deg, noise.offset_m) if noise is not None else FALLBACK_FLOOR_SIGMA
    )
    if options.floor_normal_sigma_deg is not None:
        tilt_deg = options.floor_normal_sigma_deg
    if options.floor_offset_sigma_m is not None:
        offset_m = options.floor_offset_sigma_m
    return options.model_copy(
        update={"floor_normal_sigma_deg": tilt_deg, "floor_offset_sigma_m": offset_m}
    )


class _FloorsAndNormals(TypedDict):
    planes: Sequence[Sequence[Plane | None]] | None
    floor_G: Plane | None
    normals: Sequence[Sequence[Points]]


def _floors_and_normals(state: CalibrationState) -> _FloorsAndNormals:
    """What stage 4's objective takes besides the object points: the floor planes seen and the
    floor in G (stage 3's; none when it did not run) and the object points' normals."""
    rough = state.floor_refinement
    return {
        "planes": state.floors_seen() if rough is not None else None,
        "floor_G": rough.floor_G if rough is not None else None,
        "normals": state.object_normals_in_lidar(),
    }
