"""Observability: where the reference sits in the base frame (from the floor, when the config
says how high the base is above it), then how well the data determine each LiDAR's pose
(`pipeline.observability`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from pipeline.config import PipelineConfig
from pipeline.geometry import Plane
from pipeline.observability import PoseUncertainty, level_rotation, pose_uncertainties
from pipeline.problem import LidarInfo
from pipeline.stages.runner import Listeners, StageOutcome
from pipeline.stages.state import CalibrationState, required
from pipeline.transforms import Matrix4, make_transform
from pipeline.verdict import fits_alike


def floor_pose(T_base_ref: Matrix4, floor_ref: Plane, height_m: float) -> Matrix4:
    """`T_base_ref` with height, roll and pitch from the floor (seen in the reference frame):
    base z along the floor normal, base origin `height_m` above the floor; x, y, yaw kept."""
    R_level = level_rotation(T_base_ref[:3, :3] @ floor_ref.normal)
    T = make_transform(R_level @ T_base_ref[:3, :3], R_level @ T_base_ref[:3, 3])
    # In the base frame the floor is z = -height: the reference origin is `offset` above it.
    T[2, 3] = floor_ref.offset - height_m
    return T


def floor_in_ref(state: CalibrationState) -> Plane | None:
    """Where stage 3's floor lies in the reference frame as calibrated (G is the reference at
    stop 0); None when stage 3 did not run."""
    rough = state.floor_refinement
    if rough is None:
        return None
    T_G_ref0 = state.T_G_ref[0]
    normal = T_G_ref0[:3, :3].T @ rough.floor_G.normal
    offset = rough.floor_G.offset + float(rough.floor_G.normal @ T_G_ref0[:3, 3])
    return Plane(normal=normal, offset=offset)


def run(state: CalibrationState, config: PipelineConfig, listeners: Listeners) -> StageOutcome:
    """The calibrated `T_base_ref` and every LiDAR's pose uncertainty in the level base frame."""
    floor_ref = floor_in_ref(state)
    T_base_ref = state.T_base_ref_initial
    height = config.frames.base_height_above_floor_m
    if height is not None and floor_ref is not None:
        T_base_ref = floor_pose(T_base_ref, floor_ref, height)
    uncertainties = pose_uncertainties(
        required(state.optimised, "optimisation"),
        T_base_ref,
        None if floor_ref is None else floor_ref.normal,
        config.observability,
        state.surface_shift,
        _alternative(state, config),
    )
    return StageOutcome(
        dataclasses.replace(state, T_base_ref_calibrated=T_base_ref, uncertainties=uncertainties),
        {"undetermined": sum(len(u.undetermined) for u in uncertainties)},
        _undetermined_message(state.lidars, uncertainties),
    )


def _alternative(state: CalibrationState, config: PipelineConfig) -> Matrix4 | None:
    """The extrinsics (L, 4, 4) of stage 4's other solution where the recording fits it as well
    as the kept one (the verdict's `unique_solution` fails on it); None otherwise."""
    starts, compared = state.starts_evidence(), state.start_comparison
    if starts is None or compared is None or not fits_alike(starts, config.verdict):
        return None
    return compared.other_T_ref_lidar


def _undetermined_message(
    lidars: Sequence[LidarInfo], uncertainties: Sequence[PoseUncertainty]
) -> str:
    missing = [
        f"{info.frame}: {', '.join(u.undetermined)}"
        for info, u in zip(lidars, uncertainties, strict=True)
        if u.undetermined
    ]
    return (
        "every degree of freedom determined"
        if not missing
        else "undetermined " + "; ".join(missing)
    )
