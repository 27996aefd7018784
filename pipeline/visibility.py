"""How far other LiDARs' objects lie from the surfaces the reference saw (eq. 12 without its
coverage term).

Eq. 12 (`pipeline.metric`) caps at `max_distance_m` every point of another LiDAR far from the
reference's map, whether it lies far because the calibration is off or because it sits on a part
of an object the reference never saw (a far face, a top seen from higher up, an object out of the
reference's range). After a right calibration the second kind dominates: over bench_random's
recordings eq. 12 spans 6-72 mm with the extrinsics within 5 mm, so a limit on it fails good
calibrations on the routines that show the two LiDARs different faces, and any limit low enough to
catch a few centimetres of misplacement would fail most of them.

Here a point of another LiDAR counts only where the reference's rays to objects reached it at
some stop: placed in the reference LiDAR's frame at that stop (`T_G_lidar_ref[j]^-1`), its
direction lies within `ray_angle_deg` of a ray along which the reference returned an object point
(its object points of that stop, as eq. 12 uses them), and its range is at most that ray's range
plus `range_margin_m`. Such a point lies on the object surface the reference saw or in the free
space in front of it; a point behind it (a far face), or where the reference saw no object, does
not count. Each point that counts contributes its distance to the reference's surface: along the
normal of its nearest reference object point (stage 2's local surface), capped as eq. 12's
distances are. Measured so, a right calibration leaves the range noise and the surfaces'
disagreement, not the reference's point spacing (eq. 12's nearest-point distance is 7 mm at the
median on a rosette's sparse objects, bench_random seed 1022, 3 mm from the truth); a calibration
that misplaces a LiDAR moves its points off the surfaces the reference saw, which counts in full.

Rays to the floor are left out on purpose: along the edge of an object's silhouette the nearest of
them passes beside the object, and the parts of objects segmentation dropped from the reference's
map (too small a cluster at that stop) would count as far (11-13 % of two LiDARs' seen points at
the cap on seed 1022 with them, none without).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field
from pykdtree.kdtree import KDTree

from pipeline.metric import place
from pipeline.transforms import Points, apply, invert


class VisibilityConfig(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    ray_angle_deg: float = Field(
        default=1.0,
        gt=0,
        le=10,
        description="a point lies on one of the reference's rays when its direction is within "
        "this angle of it (half the 2 deg between a 16-beam LiDAR's rings)",
    )
    range_margin_m: float = Field(
        default=0.05,
        gt=0,
        description="how far beyond where the reference's ray returned a point still counts as "
        "seen (range noise and a surface's thickness at grazing angles)",
    )
    max_rays_per_stop: int = Field(
        default=50_000,
        ge=1000,
        description="the reference's rays of one stop are thinned evenly to at most this many",
    )


@dataclass(frozen=True)
class SeenMetric:
    """Per LiDAR (reference first): `per_lidar[i]`, the mean distance of LiDAR i's object points
    the reference saw to the reference's surface there (NaN for the reference and where none was
    seen); `seen[i]` how many those were, `points[i]` of how many."""

    per_lidar: tuple[float, ...]
    seen: tuple[int, ...]
    points: tuple[int, ...]


def seen_metric(
    objects: Sequence[Sequence[Points]],
    normals: Sequence[Points],
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
    config: VisibilityConfig,
    cap_m: float,
) -> SeenMetric:
    """`SeenMetric` for `objects[lidar][stop]` ((N, 3) in the LiDAR's frame; LiDAR 0 the
    reference, whose object points' unit normals are `normals[stop]`) placed with `T_G_ref`
    (J, 4, 4) and `T_ref_lidar` (L, 4, 4), each distance capped at `cap_m` (eq. 12's cap)."""
    T_G_lidar_ref = T_G_ref @ T_ref_lidar[0]
    reference = place(objects[0], T_G_ref, T_ref_lidar, 0)
    reference_normals = np.concatenate(
        [np.zeros((0, 3))]
        + [n @ T[:3, :3].T for n, T in zip(normals, T_G_lidar_ref, strict=True) if len(n)]
    )
    tree = KDTree(reference) if len(reference) else None
    rays = [ReferenceRays.of(cloud, config) for cloud in objects[0]]
    per_lidar, seen, points = [math.nan], [0], [len(reference)]
    for lidar in range(1, len(objects)):
        placed = place(objects[lidar], T_G_ref, T_ref_lidar, lidar)
        mask = np.zeros(len(placed), dtype=bool)
        if tree is not None and len(placed):
            mask = seen_by_reference(placed, rays, T_G_lidar_ref, config)
        count = int(np.count_nonzero(mask))
        mean = math.nan
        if tree is not None and count:
            _, nearest = tree.query(placed[mask], k=1)
            offset = placed[mask] - reference[nearest]
            along_normal = np.abs(np.einsum("ij,ij->i", offset, reference_normals[nearest]))
            # fmin: a point whose reference normal is undefined (NaN) counts as far, at the cap
            mean = float(np.mean(np.fmin(along_normal, cap_m)))
        per_lidar.append(mean)
        seen.append(count)
        points.append(len(placed))
    return SeenMetric(tuple(per_lidar), tuple(seen), tuple(points))


@dataclass(frozen=True)
class ReferenceRays:
    """One stop of the reference: its rays' unit directions in a k-d tree (None: no ray) and
    their ranges (metres)."""

    tree: KDTree | None
    ranges: NDArray[np.float64]

    @classmethod
    def of(cls, cloud: Points, config: VisibilityConfig) -> ReferenceRays:
        step = max(1, math.ceil(len(cloud) / config.max_rays_per_stop))
        thinned = np.asarray(cloud[::step], dtype=np.float64)
        ranges = np.linalg.norm(thinned, axis=1)
        returned = ranges > 0
        thinned, ranges = thinned[returned], ranges[returned]
        if len(thinned) == 0:
            return cls(None, ranges)
        return cls(KDTree(thinned / ranges[:, None]), ranges)


def seen_by_reference(
    points_G: Points,
    rays: Sequence[ReferenceRays],
    T_G_lidar_ref: NDArray[np.float64],
    config: VisibilityConfig,
) -> NDArray[np.bool_]:
    """Which of `points_G` (N, 3) the reference's rays reached at one stop or more."""
    seen = np.zeros(len(points_G), dtype=bool)
    chord = 2.0 * math.sin(math.radians(config.ray_angle_deg) / 2.0)
    for stop, T_G_lidar in zip(rays, T_G_lidar_ref, strict=True):
        todo = np.flatnonzero(~seen)
        if stop.tree is None or len(todo) == 0:
            continue
        local = apply(invert(T_G_lidar), points_G[todo])
        ranges = np.linalg.norm(local, axis=1)
        ahead = ranges > 0
        todo, local, ranges = todo[ahead], local[ahead], ranges[ahead]
        _, ray = stop.tree.query(local / ranges[:, None], k=1, distance_upper_bound=chord)
        on_ray = ray < len(stop.ranges)
        reached = np.zeros(len(todo), dtype=bool)
        reached[on_ray] = ranges[on_ray] <= stop.ranges[ray[on_ray]] + config.range_margin_m
        seen[todo[reached]] = True
    return seen
