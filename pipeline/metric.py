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

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field
from pykdtree.kdtree import KDTree

from pipeline.geometry import voxel_keys
from pipeline.transforms import Points, pose_difference


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
    objects); `points[i]`: how many points of LiDAR i entered; `capped[i]`: their capped
    distances, what the means average (empty for the reference)."""

    value: float
    per_lidar: tuple[float, ...]
    points: tuple[int, ...]
    capped: tuple[NDArray[np.float64], ...] = ()


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
    return metric_of(capped_distances(objects, T_G_ref, T_ref_lidar, config))


def metric_of(distances: Sequence[CappedDistances]) -> MetricError:
    """Eq. 12 from the capped distances `capped_distances` measured (reference first)."""
    per_lidar = [float("nan")] + [
        float(np.mean(d.capped)) if len(d.capped) else float("nan") for d in distances[1:]
    ]
    counts = [len(d.points_G) for d in distances]
    every = np.concatenate([np.zeros(0)] + [d.capped for d in distances[1:]])
    value = float(np.mean(every)) if len(every) else float("nan")
    return MetricError(
        value=value,
        per_lidar=tuple(per_lidar),
        points=tuple(counts),
        capped=tuple(d.capped for d in distances),
    )


@dataclass(frozen=True)
class CappedDistances:
    """One LiDAR's object points placed in G (N, 3) and, for a non-reference LiDAR, each one's
    distance to the reference's map capped at `max_distance_m` (N,; empty for the reference and
    where the reference has no points)."""

    points_G: Points
    capped: NDArray[np.float64]


def capped_distances(
    objects: Sequence[Sequence[Points]],
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
    config: MetricConfig,
) -> list[CappedDistances]:
    """Per LiDAR (reference first), what eq. 12 averages: see `CappedDistances`."""
    reference = place(objects[0], T_G_ref, T_ref_lidar, 0)
    out = [CappedDistances(reference, np.zeros(0))]
    tree = KDTree(reference) if len(reference) else None
    for lidar in range(1, len(objects)):
        points = place(objects[lidar], T_G_ref, T_ref_lidar, lidar)
        if tree is None or len(points) == 0:
            out.append(CappedDistances(points, np.zeros(0)))
            continue
        distance, _ = tree.query(points, k=1)
        out.append(CappedDistances(points, np.minimum(distance, config.max_distance_m)))
    return out


@dataclass(frozen=True)
class SolutionComparison:
    """Two solutions of stage 4 on the same object points, the kept one against the other.

    `apart_translation_m` / `apart_rotation_deg`: how far apart their extrinsics lie (the
    largest over the non-reference LiDARs). `difference_m`: how much nearer the reference's map
    the kept solution places the points, point by point (eq. 12 of the other less eq. 12 of the
    kept: positive when the kept one fits better). `stderr_m`: that difference's standard error,
    a leave-one-block-out jackknife over `blocks` cubic blocks of space (the points of one surface
    patch err together, so they are left out together). `other_T_ref_lidar` (L, 4, 4): the other
    solution's extrinsics."""

    apart_translation_m: float
    apart_rotation_deg: float
    difference_m: float
    stderr_m: float
    blocks: int
    other_T_ref_lidar: NDArray[np.float64] | None = None

    @property
    def separation_sigmas(self) -> float:
        """`difference_m` in standard errors (infinite for a difference without spread; NaN
        where there was nothing to compare or too few blocks to tell the spread)."""
        if not (math.isfinite(self.difference_m) and math.isfinite(self.stderr_m)):
            return math.nan
        if self.stderr_m > 0.0:
            return self.difference_m / self.stderr_m
        return math.inf if self.difference_m > 0.0 else 0.0


def compare_solutions(
    kept: Sequence[CappedDistances],
    other: Sequence[CappedDistances],
    kept_T_ref_lidar: NDArray[np.float64],
    other_T_ref_lidar: NDArray[np.float64],
    block_m: float,
) -> SolutionComparison:
    """`SolutionComparison` of two solutions for the same object points, from what
    `capped_distances` measured under each (reference first) and their extrinsics (L, 4, 4);
    the blocks (edge `block_m`, metres) are cells of G where the kept solution places the
    points."""
    difference = np.concatenate(
        [np.zeros(0)] + [t.capped - o.capped for o, t in zip(kept[1:], other[1:], strict=True)]
    )
    placed = np.concatenate([np.zeros((0, 3))] + [o.points_G for o in kept[1:] if len(o.capped)])
    apart = [
        pose_difference(a, b)
        for a, b in zip(kept_T_ref_lidar[1:], other_T_ref_lidar[1:], strict=True)
    ]
    translation = max((t for t, _ in apart), default=0.0)
    rotation = max((r for _, r in apart), default=0.0)
    if len(difference) == 0:
        return SolutionComparison(translation, rotation, math.nan, math.nan, 0, other_T_ref_lidar)
    keys = voxel_keys(placed, block_m, "optimisation.uncertainty_block_m")
    _, block_of = np.unique(keys, return_inverse=True)
    block_of = block_of.reshape(-1)
    n = int(block_of.max()) + 1
    sums = np.bincount(block_of, weights=difference, minlength=n)
    counts = np.bincount(block_of, minlength=n)
    mean = float(np.mean(difference))
    if n < 2:
        return SolutionComparison(translation, rotation, mean, math.nan, n, other_T_ref_lidar)
    left_out = (sums.sum() - sums) / (counts.sum() - counts)
    stderr = float(np.sqrt((n - 1) / n * np.sum((left_out - left_out.mean()) ** 2)))
    return SolutionComparison(translation, rotation, mean, stderr, n, other_T_ref_lidar)
