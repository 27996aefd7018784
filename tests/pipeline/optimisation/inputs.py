"""Stage 4's inputs on the shared box scenario: segmentation's clouds and stage 3's poses."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

from pipeline.geometry import Plane
from pipeline.rough_refinement import (
    RoughRefinementConfig,
    RoughRefinementResult,
    refine_with_floor,
)
from pipeline.segmentation import SurfaceModel
from pipeline.stages.state import CalibrationState
from pipeline.transforms import Points
from tests.pipeline.calibration_data import box_prepared


@dataclass(frozen=True)
class StageInputs:
    prepared: CalibrationState
    planes: list[list[Plane | None]]
    rough: RoughRefinementResult
    objects: list[list[Points]]
    normals: list[list[Points]]


@cache
def stage_inputs(surface_model: SurfaceModel | None = None) -> StageInputs:
    prepared, segments = box_prepared(surface_model)
    planes = [[s.floor for s in row] for row in segments]
    rough = refine_with_floor(
        planes, prepared.T_G_ref, prepared.T_ref_lidar, RoughRefinementConfig()
    )
    objects = [[s.object_points for s in row] for row in segments]
    normals = [[s.object_normals for s in row] for row in segments]
    return StageInputs(prepared, planes, rough, objects, normals)
