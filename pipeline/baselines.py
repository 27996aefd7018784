"""The paper's comparison methods, on the same data and the same optimiser, for the benchmark.

- entire cloud: the same cost on every (voxelised) point, no segmentation, no floor stage;
- proposed without rough refinement: segmentation and the object optimisation, but neither the
  floor stage nor the floor terms it feeds (as in the paper's "w.o. RR").
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.calibrate import CalibrationResult, calibrate, prepare
from pipeline.config import PipelineConfig, config_from_mapping, resolved
from pipeline.downsample import voxel_downsample
from pipeline.optimisation import OptimisationResult, optimise
from pipeline.problem import CalibrationProblem
from pipeline.surfaces import local_planes


@dataclass(frozen=True)
class BaselineResult:
    """Extrinsics of a baseline: `frames` (reference first), `T_base_lidar` (L, 4, 4) with the
    reference kept at its initial pose, and the optimiser's record."""

    frames: tuple[str, ...]
    T_base_lidar: NDArray[np.float64]
    optimisation: OptimisationResult
    seconds: float

    def T_base_lidar_per_iteration(self, frame: str) -> NDArray[np.float64]:
        """(K + 1, 4, 4): this LiDAR's `T_base_lidar` before each step and at the end."""
        index = self.frames.index(frame)
        history: NDArray[np.float64] = (
            self.T_base_lidar[0] @ self.optimisation.T_ref_lidar_per_iteration[:, index]
        )
        return history


def entire_cloud(
    problem: CalibrationProblem,
    config: PipelineConfig | None = None,
    *,
    voxel_size_m: float = 0.05,
    max_points_per_cloud: int | None = 3000,
) -> BaselineResult:
    """Every point of every cloud in the object optimisation, with the proposed method's cost
    (as the paper did) but no floor stage and no floor terms.

    The clouds are downsampled to `voxel_size_m` and their surfaces fitted and smoothed like the
    proposed method's objects; `max_points_per_cloud` then caps each (LiDAR, stop) cloud by
    random sampling, since the floor alone is thousands of voxels per cloud.
    """
    started = time.perf_counter()
    config = config or PipelineConfig()
    prepared = prepare(problem, config)
    neighbours = config.segmentation.surface_neighbours
    surfaces = [
        [
            local_planes(
                voxel_downsample(prepared.filtered(lidar, stop)[0], voxel_size_m), neighbours
            )
            for stop in range(len(row))
        ]
        for lidar, row in enumerate(prepared.clouds_in_lidar)
    ]
    optimisation = config.optimisation.model_copy(
        update={"floor_terms": False, "max_points_per_cloud": max_points_per_cloud}
    )
    result = optimise(
        [[points for points, _ in row] for row in surfaces],
        prepared.T_G_ref,
        prepared.T_ref_lidar,
        optimisation,
        normals=[[normals for _, normals in row] for row in surfaces],
    )
    T_base_ref = prepared.lidars[0].T_base_lidar
    return BaselineResult(
        frames=tuple(lidar.frame for lidar in prepared.lidars),
        T_base_lidar=np.stack([T_base_ref @ T for T in result.T_ref_lidar]),
        optimisation=result,
        seconds=time.perf_counter() - started,
    )


def without_rough_refinement(
    problem: CalibrationProblem, config: PipelineConfig | None = None
) -> CalibrationResult:
    """The proposed pipeline with stage 3 (and so the floor terms of stage 4) switched off."""
    data = resolved(config or PipelineConfig())
    data["rough_refinement"]["enabled"] = False
    return calibrate(problem, config_from_mapping(data))
