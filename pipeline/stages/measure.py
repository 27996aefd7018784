"""The metric error (eq. 12, `pipeline.metric`) of the object maps, where the poses started and
where the stages before left them."""

from __future__ import annotations

import dataclasses
import math

from pipeline.config import PipelineConfig
from pipeline.metric import metric_error
from pipeline.stages.runner import Listeners, StageOutcome
from pipeline.stages.state import CalibrationState
from pipeline.visibility import seen_metric


def run(state: CalibrationState, config: PipelineConfig, listeners: Listeners) -> StageOutcome:
    """The metric of the initial and of the current poses (the latter measured already where
    stage 4 chose between two starts by it), and the latter over what the reference saw."""
    objects = state.objects_in_lidar()
    initial = metric_error(objects, state.T_G_ref_initial, state.T_ref_lidar_initial, config.metric)
    final = state.metric_final or metric_error(
        objects, state.T_G_ref, state.T_ref_lidar, config.metric
    )
    seen = seen_metric(
        objects,
        state.object_normals_in_lidar()[0],
        state.T_G_ref,
        state.T_ref_lidar,
        config.visibility,
        config.metric.max_distance_m,
    )
    worst_seen = max((m for m in seen.per_lidar if math.isfinite(m)), default=math.nan)
    return StageOutcome(
        dataclasses.replace(state, metric_initial=initial, metric_final=final, metric_seen=seen),
        {"initial_m": initial.value, "final_m": final.value, "final_seen_m": worst_seen},
        f"{initial.value:.4f} m -> {final.value:.4f} m ({worst_seen:.4f} m where the reference "
        "saw, worst LiDAR)",
    )
