"""Stage 4, the optimisation: every LiDAR's object points against the reference's, with the
floor terms when stage 3 gave a floor (`pipeline.optimisation`)."""

from __future__ import annotations

import dataclasses
from functools import partial

from pipeline.config import PipelineConfig
from pipeline.optimisation import optimise
from pipeline.stages.runner import IterationProgress, Listeners, StageOutcome
from pipeline.stages.state import CalibrationState, Detail


def _iteration_of(on_iteration: IterationProgress, max_iterations: int, iteration: int) -> None:
    on_iteration(iteration, max_iterations)


def run(state: CalibrationState, config: PipelineConfig, listeners: Listeners) -> StageOutcome:
    """Refine `T_G_ref` and `T_ref_lidar` on the objects; `listeners.on_iteration` hears of
    every iteration."""
    rough = state.floor_refinement
    on_iteration = listeners.on_iteration
    result = optimise(
        state.objects_in_lidar(),
        state.T_G_ref,
        state.T_ref_lidar,
        config.optimisation,
        planes=state.floors_seen() if rough is not None else None,
        floor_G=rough.floor_G if rough is not None else None,
        normals=state.object_normals_in_lidar(),
        on_iteration=None
        if on_iteration is None
        else partial(_iteration_of, on_iteration, config.optimisation.max_iterations),
        range_bias=config.observability.range_bias == "estimated",
    )
    details: dict[str, Detail] = {
        "iterations": result.iterations,
        "converged": result.converged,
        "residual": config.optimisation.residual,
        "residual_rms_m": result.residual_rms_m,
    }
    new_state = dataclasses.replace(
        state, optimised=result, T_G_ref=result.T_G_ref, T_ref_lidar=result.T_ref_lidar
    )
    message = (
        f"{result.iterations} iterations, {'converged' if result.converged else 'NOT converged'}"
    )
    return StageOutcome(new_state, details, message)
