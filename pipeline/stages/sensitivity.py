"""The surfaces' sensitivity: stage 4 run again from its solution on object points smoothed
further or onto another surface model, and how far each pose moves
(`observability.surface_sensitivity_passes`, `observability.surface_sensitivity_model`).

Why: under range noise the smoothed object surfaces settle a few millimetres off the true ones,
and every stop and every patch of a surface repeats that offset, so the jackknifes cannot see
what it does to the poses (bench_random seed 1060: 10.1 mm off with a jackknife 1-sigma of
0.3 mm). Projecting the points onto their surfaces again thins the noisy sheet and moves that
offset: the solution's shift measures how much the calibration rests on it, and the
observability stage adds it to the reported 1-sigma as a systematic error, less the spread that
chance alone would give it (a jackknife over stops of the linearised shift). The poses
themselves stay those of stage 4.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from pipeline.config import PipelineConfig
from pipeline.geometry import log_se3
from pipeline.observability import SurfaceShift, shift_chance_covariance
from pipeline.optimisation.layout import ParameterLayout
from pipeline.segmentation import Segmentation, SurfaceModel
from pipeline.stages.joint_optimise import evaluate_solution, optimise_from
from pipeline.stages.runner import Listeners, StageOutcome
from pipeline.stages.segment import segment_all
from pipeline.stages.state import CalibrationState, Detail, PerCloud, required
from pipeline.transforms import Matrix4, invert, pose_difference


def twist_between(T_from: Matrix4, T_to: Matrix4) -> NDArray[np.float64]:
    """(6,) the left twist `[rho, phi]` that takes `T_from` to `T_to` (`T_to = exp(xi) T_from`),
    as the optimiser moves its poses."""
    return log_se3(T_to @ invert(T_from))


def shift_vector(
    layout: ParameterLayout,
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
    moved_T_G_ref: NDArray[np.float64],
    moved_T_ref_lidar: NDArray[np.float64],
) -> NDArray[np.float64]:
    """(P,) the optimiser's state vector from one solution to another (stop 0 and the reference
    are fixed and have no columns)."""
    shift = np.zeros(layout.size)
    for stop in range(1, layout.n_stops):
        col = layout.stop(stop)
        shift[col : col + 6] = twist_between(T_G_ref[stop], moved_T_G_ref[stop])
    for lidar in range(1, layout.n_lidars):
        col = layout.lidar(lidar)
        shift[col : col + 6] = twist_between(T_ref_lidar[lidar], moved_T_ref_lidar[lidar])
    return shift


def run(state: CalibrationState, config: PipelineConfig, listeners: Listeners) -> StageOutcome:
    """Segment again with the surfaces `surface_change` gives (more projections, another
    surface model), run stage 4 from its solution on those points (its iterations are not
    progress: no bar goes back) and keep the shift of every pose, with the spread chance alone
    would give it (the jackknife over stops of the two objectives' difference at the
    solution); nothing when the config leaves it out."""
    change = surface_change(config)
    if not change:
        return StageOutcome(state, {"enabled": False}, "not measured (off)")
    optimised = required(state.optimised, "optimisation")
    refitted = dataclasses.replace(state, segments=refitted_segments(state, config, change))
    moved = optimise_from(refitted, config, Listeners(), (state.T_G_ref, state.T_ref_lidar), 1)
    shift = shift_vector(
        optimised.layout, state.T_G_ref, state.T_ref_lidar, moved.T_G_ref, moved.T_ref_lidar
    )
    chance = shift_chance_covariance(
        optimised, evaluate_solution(refitted, config), config.observability
    )
    details: dict[str, Detail] = {"enabled": True, **change, "iterations": moved.iterations}
    largest = 0.0
    for lidar in range(1, optimised.layout.n_lidars):
        moved_m, turned_deg = pose_difference(state.T_ref_lidar[lidar], moved.T_ref_lidar[lidar])
        frame = state.lidars[lidar].frame
        details[f"shift_m:{frame}"] = moved_m
        details[f"shift_deg:{frame}"] = turned_deg
        largest = max(largest, moved_m)
    return StageOutcome(
        dataclasses.replace(state, surface_shift=SurfaceShift(shift, chance)),
        details,
        f"the solution moves up to {1e3 * largest:.1f} mm on surfaces re-fitted ("
        + ", ".join(_describe(key, value) for key, value in change.items())
        + ")",
    )


def refitted_segments(
    state: CalibrationState, config: PipelineConfig, change: dict[str, int | str]
) -> PerCloud[Segmentation]:
    """`state`'s clouds segmented with `change` (`surface_change`) made to `config`'s
    segmentation. Where it only swaps the beam
    quadric (one pass, no debias, smoothed objects) for the quadric, the beam quadric's fit
    already placed the points on the quadric on the way (`Segmentation.quadric_object_points`,
    the same normals and points kept; None where a cloud had too few points for a quadric,
    whose plane fit both models share): no second fit. Otherwise segmented again."""
    own = config.segmentation
    shared_fit = (
        change == {"surface_model": "quadric"}
        and own.surface_model == "beam_quadric"
        and own.surface_passes == 1
        and own.surface_debias == "none"
        and own.smooth_objects
    )
    if not shared_fit:
        other = config.model_copy(update={"segmentation": own.model_copy(update=change)})
        return segment_all(state, other)
    return tuple(
        tuple(
            dataclasses.replace(
                s,
                object_points=s.object_points
                if s.quadric_object_points is None
                else s.quadric_object_points,
            )
            for s in row
        )
        for row in required(state.segments, "segmentation")
    )


def surface_change(config: PipelineConfig) -> dict[str, int | str]:
    """The segmentation settings the sensitivity re-run changes (`surface_passes`,
    `surface_model`), from `observability`'s; empty when it is off."""
    observability = config.observability
    change: dict[str, int | str] = {}
    if observability.surface_sensitivity_passes is not None:
        change["surface_passes"] = observability.surface_sensitivity_passes
    model = observability.surface_sensitivity_model
    if model is not None:
        change["surface_model"] = (
            alternative_model(config.segmentation.surface_model)
            if model == "alternative"
            else model
        )
    return change


def alternative_model(own: SurfaceModel) -> SurfaceModel:
    """The surface model the sensitivity re-run compares `own` with: the quadric fitted along
    its patch's normal where `own` fits along the beams, else the beam quadric."""
    return "quadric" if own in ("beam_quadric", "beam_fit") else "beam_quadric"


def _describe(setting: str, value: int | str) -> str:
    """One changed segmentation setting in words: `surface_passes` 4 -> "4 projections"."""
    if setting == "surface_passes":
        return f"{value} projections"
    return f"the {str(value).replace('_', ' ')} model"
