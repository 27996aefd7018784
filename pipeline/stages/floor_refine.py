"""Stage 3, rough refinement: the poses moved so that every LiDAR's floor at every stop lies on
one floor in G (`pipeline.rough_refinement`); skipped when disabled."""

from __future__ import annotations

import dataclasses

from pipeline.config import PipelineConfig
from pipeline.rough_refinement import refine_with_floor
from pipeline.stages.runner import Listeners, StageOutcome
from pipeline.stages.state import CalibrationState, Detail


def run(state: CalibrationState, config: PipelineConfig, listeners: Listeners) -> StageOutcome:
    """Refine `T_G_ref` and `T_ref_lidar` on the floors segmentation found."""
    if not config.rough_refinement.enabled:
        return StageOutcome(state, {"enabled": False}, "skipped")
    rough = refine_with_floor(
        state.floors_seen(), state.T_G_ref, state.T_ref_lidar, config.rough_refinement
    )
    details: dict[str, Detail] = {
        "enabled": True,
        "iterations": rough.iterations,
        "converged": rough.converged,
        "planes": rough.observations,
        "tilt_rms_deg_initial": rough.residual_initial.tilt_deg,
        "tilt_rms_deg_final": rough.residual_final.tilt_deg,
        "offset_rms_m_initial": rough.residual_initial.offset_m,
        "offset_rms_m_final": rough.residual_final.offset_m,
    }
    message = (
        f"{rough.observations} floor planes agree to {rough.residual_final.tilt_deg:.3f} deg"
        f" / {rough.residual_final.offset_m * 1000:.1f} mm"
    )
    new_state = dataclasses.replace(
        state, floor_refinement=rough, T_G_ref=rough.T_G_ref, T_ref_lidar=rough.T_ref_lidar
    )
    return StageOutcome(new_state, details, message)
