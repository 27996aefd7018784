"""Stage 2, segmentation: each cloud as stage 1 left it, split on its floor into the floor plane
and the object points above it (`pipeline.segmentation`)."""

from __future__ import annotations

import dataclasses

from pipeline.config import PipelineConfig
from pipeline.segmentation import Segmentation, segment_on_floor
from pipeline.stages.runner import Listeners, StageOutcome
from pipeline.stages.state import CalibrationState, Detail, PerCloud, per_cloud


def segment_all(state: CalibrationState, config: PipelineConfig) -> PerCloud[Segmentation]:
    """Every cloud segmented on the floor fitted before stage 1, per LiDAR and stop."""

    def segmented(at: tuple[int, int]) -> Segmentation:
        cloud, floor = state.filtered(*at)
        return segment_on_floor(cloud, config.segmentation, floor)

    return per_cloud(state.clouds_in_lidar, segmented)


def run(state: CalibrationState, config: PipelineConfig, listeners: Listeners) -> StageOutcome:
    """Segment every cloud. The floors were fitted before stage 1 (it judges what stands on
    them): their time counts here."""
    segments = segment_all(state, config)
    details: dict[str, Detail] = {
        "floor_seconds": state.floor_seconds,
        "object_points": sum(len(s.object_points) for row in segments for s in row),
        "floor_planes": sum(s.floor is not None for row in segments for s in row),
        "clusters": sum(s.cluster_count for row in segments for s in row),
    }
    return StageOutcome(
        dataclasses.replace(state, segments=segments),
        details,
        f"{details['object_points']} object points, {details['floor_planes']} floor planes",
        credited_seconds=state.floor_seconds,
    )
