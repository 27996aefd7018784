"""Between stages 3 and 4: the planar search over each LiDAR's rotation about the floor normal and
shift along the floor (`pipeline.global_alignment`); skipped where the config disables it."""

from __future__ import annotations

import dataclasses

from pipeline.config import PipelineConfig
from pipeline.global_alignment import align_globally
from pipeline.stages.runner import Listeners, StageOutcome
from pipeline.stages.state import CalibrationState, Detail


def run(state: CalibrationState, config: PipelineConfig, listeners: Listeners) -> StageOutcome:
    """Move each non-reference `T_ref_lidar` to its best-scoring planar candidate, or (`choose:
    refined`) leave the candidate to stage 4 as a second start; needs stage 3's floor (without it
    the stage is skipped)."""
    rough = state.floor_refinement
    if not config.global_alignment.enabled:
        return StageOutcome(state, {"enabled": False}, "skipped")
    if rough is None:
        return StageOutcome(state, {"enabled": True, "skipped": "no floor"}, "skipped: no floor")
    result = align_globally(
        state.objects_in_lidar(),
        state.T_G_ref,
        state.T_ref_lidar,
        rough.floor_G,
        config.global_alignment,
    )
    frames = [lidar.frame for lidar in state.lidars[1:]]
    details: dict[str, Detail] = {"enabled": True}
    for frame, move in zip(frames, result.moves, strict=True):
        details[f"{frame}_rotation_deg"] = move.rotation_deg
        details[f"{frame}_shift_x_m"] = move.shift_m[0]
        details[f"{frame}_shift_y_m"] = move.shift_m[1]
        details[f"{frame}_score_gain"] = (
            move.score_best / move.score_current if move.score_current > 0 else 0.0
        )
        details[f"{frame}_adopted"] = move.adopted
    moved = [frame for frame, move in zip(frames, result.moves, strict=True) if move.adopted]
    if not moved:
        return StageOutcome(state, details, "every LiDAR kept where stage 3 left it")
    if config.global_alignment.choose == "refined":
        second = (result.T_G_ref, result.T_ref_lidar)
        message = f"a second start for stage 4 with {', '.join(moved)} moved"
        return StageOutcome(dataclasses.replace(state, second_start=second), details, message)
    new_state = dataclasses.replace(state, T_G_ref=result.T_G_ref, T_ref_lidar=result.T_ref_lidar)
    return StageOutcome(new_state, details, f"moved {', '.join(moved)}")
