"""The metric error (eq. 12, `pipeline.metric`) of the object maps, where the poses started and
where the stages before left them."""

from __future__ import annotations

import dataclasses

from pipeline.config import PipelineConfig
from pipeline.metric import metric_error
from pipeline.stages.runner import Listeners, StageOutcome
from pipeline.stages.state import CalibrationState


def run(state: CalibrationState, config: PipelineConfig, listeners: Listeners) -> StageOutcome:
    """The metric of the initial and of the current poses (the latter measured already where
    stage 4 chose between two starts by it)."""
    objects = state.objects_in_lidar()
    initial = metric_error(objects, state.T_G_ref_initial, state.T_ref_lidar_initial, config.metric)
    final = state.metric_final or metric_error(
        objects, state.T_G_ref, state.T_ref_lidar, config.metric
    )
    return StageOutcome(
        dataclasses.replace(state, metric_initial=initial, metric_final=final),
        {"initial_m": initial.value, "final_m": final.value},
        f"{initial.value:.4f} m -> {final.value:.4f} m",
    )
