"""The metric error (paper eq. 12): how far the calibrated LiDARs' maps lie from the reference map.

Exactly which points enter: the *object* points of segmentation (stage 2: at least
`object_min_height_m` above the floor, voxelised to `voxel_size_m`, in clusters of at least
`min_cluster_points`, projected onto their local plane, edge-on points dropped), of every stop,
placed in the global frame G with the poses being judged (`T_G_ref(stop) @ T_ref_lidar`); the
same points before and after calibration, only the poses differ. The reference map is
the reference LiDAR's object points of all stops; every object point of every other LiDAR
contributes its Euclidean distance to its nearest neighbour in that map, capped at
`max_distance_m` (so parts of an object the reference never saw count as "far", not as
"infinitely far"). The metric is the mean over all those points of all non-reference LiDARs:
`sum_i sum_p min(d(p), cap) / sum_i N_i`, in metres. The floor is left out on purpose: it
matches under any x, y and yaw and would hide exactly the errors this is meant to show.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field
from pykdtree.kdtree import KDTree

from pipeline.transforms import Points


class MetricConfig(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    max_distance_m: float = Field(
        default=0.1,
        gt=0,
        description="nearest-neighbour distances are capped at this before averaging",
    )


@dataclass(frozen=True)
class MetricError:
    """`value`: eq. 12 in metres (NaN when there is nothing to compare). `per_lidar[i]`: the
    same mean over LiDAR i's points alone (NaN for the reference and for LiDARs without
    objects); `points[i]`: how many points of LiDAR i entered."""

    value: float
    per_lidar: tuple[float, ...]
    points: tuple[int, ...]


def place(
    clouds: Sequence[Points],
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
    lidar: int,
) -> Points:
    """One LiDAR's clouds (one per stop, (N_j, 3) in its frame) stacked in G, (sum N_j, 3)."""
    placed = [
        cloud @ (T_G_ref[j] @ T_ref_lidar[lidar])[:3, :3].T
        + (T_G_ref[j] @ T_ref_lidar[lidar])[:3, 3]
        for j, cloud in enumerate(clouds)
        if len(cloud)
    ]
    return np.concatenate(placed) if placed else np.zeros((0, 3))


def metric_error(
    objects: Sequence[Sequence[Points]],
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
    config: MetricConfig,
) -> MetricError:
    """Eq. 12 for `objects[lidar][stop]` ((N, 3) in the LiDAR's frame; LiDAR 0 the reference)
    placed with `T_G_ref` (J, 4, 4) and `T_ref_lidar` (L, 4, 4)."""
    reference = place(objects[0], T_G_ref, T_ref_lidar, 0)
    per_lidar = [float("nan")]
    counts = [len(reference)]
    total, count = 0.0, 0
    tree = KDTree(reference) if len(reference) else None
    for lidar in range(1, len(objects)):
        points = place(objects[lidar], T_G_ref, T_ref_lidar, lidar)
        counts.append(len(points))
        if tree is None or len(points) == 0:
            per_lidar.append(float("nan"))
            continue
        distance, _ = tree.query(points, k=1)
        capped = np.minimum(distance, config.max_distance_m)
        per_lidar.append(float(np.mean(capped)))
        total += float(np.sum(capped))
        count += len(points)
    value = total / count if count else float("nan")
    return MetricError(value=value, per_lidar=tuple(per_lidar), points=tuple(counts))
