"""The joint optimisation's objective: the object clouds it aligns and the floor planes it holds,
prepared once, and every cloud placed in G for a given set of poses.

Built once per phase (the coarse phase keeps fewer points per cloud); the poses are not part of
it, so that trial steps can be evaluated against the same data.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.geometry import Plane
from pipeline.optimisation.config import FALLBACK_FLOOR_SIGMA, OptimisationConfig
from pipeline.optimisation.layout import ParameterLayout
from pipeline.rough_refinement import PlaneObservation, plane_observations
from pipeline.surfaces import local_planes, orient_towards_origin
from pipeline.transforms import Matrix4, Points

CloudPart = tuple[int, int, Points]
"""One (LiDAR, stop) object cloud: `(lidar, stop, points (N, 3) in that LiDAR's frame)`."""


@dataclass(frozen=True)
class Clouds:
    """Object clouds concatenated: rows of (lidar, stop) slices, points in their own frame."""

    points: Points
    lidar: NDArray[np.int64]
    stop: NDArray[np.int64]
    slices: tuple[tuple[int, int, int, int], ...]  # (lidar, stop, start, end)

    @staticmethod
    def build(parts: Sequence[CloudPart]) -> Clouds:
        slices, start = [], 0
        for lidar, stop, pts in parts:
            slices.append((lidar, stop, start, start + len(pts)))
            start += len(pts)
        points = np.concatenate([p for *_, p in parts]) if parts else np.zeros((0, 3))
        sizes = [len(p) for *_, p in parts]
        lidar_of = np.repeat(np.array([i for i, *_ in parts], dtype=np.int64), sizes)
        stop_of = np.repeat(np.array([j for _, j, _ in parts], dtype=np.int64), sizes)
        return Clouds(
            np.ascontiguousarray(points, dtype=np.float64), lidar_of, stop_of, tuple(slices)
        )

    def transformed(self, poses: Sequence[Matrix4], vectors: Points | None = None) -> Points:
        """Each slice's points (or `vectors`, rotated only) mapped by `poses[slice]` (4, 4)."""
        source = self.points if vectors is None else vectors
        out = np.empty_like(source)
        for (_, _, a, b), T in zip(self.slices, poses, strict=True):
            out[a:b] = source[a:b] @ T[:3, :3].T
            if vectors is None:
                out[a:b] += T[:3, 3]
        return out


@dataclass(frozen=True)
class PlacedClouds:
    """Every cloud placed with one set of poses: sources in the reference frame of their stop
    (`source_ref`) and in G, the target maps in the same two frames and their normals in G."""

    source_ref: Points
    source_G: Points
    source_normals_G: Points
    reference_ref: Points
    reference_G: Points
    normals_G: Points


@dataclass(frozen=True)
class JointObjective:
    """The data of the joint optimisation's cost: source clouds (matched to a target map),
    target clouds (the reference LiDAR's map, and every LiDAR's own under
    `lidar_self_consistency` or `cross_pairs: every_lidar`), their surface normals, and the
    floor observations held against `floor_G` (empty without floor terms). `source_starts`:
    first row of each source slice."""

    config: OptimisationConfig
    layout: ParameterLayout
    sources: Clouds
    source_normals: Points
    source_starts: NDArray[np.int64]
    reference: Clouds
    reference_normals: Points
    floor: tuple[PlaneObservation, ...]
    floor_G: Plane | None
    stop_anchor: NDArray[np.float64] | None = None

    @staticmethod
    def build(
        objects: Sequence[Sequence[Points]],
        planes: Sequence[Sequence[Plane | None]] | None,
        floor_G: Plane | None,
        n_stops: int,
        config: OptimisationConfig,
        normals: Sequence[Sequence[Points]] | None = None,
        stop_anchor: NDArray[np.float64] | None = None,
    ) -> JointObjective:
        """The objective over `objects[lidar][stop]` (see `optimise` for the arguments)."""
        parts, kept = _sampled(objects, config)
        parts, part_normals = _with_normals(parts, kept, normals, config)
        # Targets: the reference LiDAR's map, and every LiDAR's own when it is kept consistent or
        # paired with the others'.
        every_lidar = config.pairs_every_lidar(len(objects))
        is_target = [p[0] == 0 or config.lidar_self_consistency or every_lidar for p in parts]
        reference, reference_normals = _stacked(parts, part_normals, is_target)
        used = [p[0] > 0 or config.reference_self_consistency or every_lidar for p in parts]
        sources, source_normals = _stacked(parts, part_normals, used)
        floor: tuple[PlaneObservation, ...] = ()
        if planes is not None and floor_G is not None and config.floor_terms:
            floor = tuple(plane_observations(planes))
        return JointObjective(
            config=config,
            layout=ParameterLayout(n_stops, len(objects)),
            sources=sources,
            source_normals=source_normals,
            source_starts=np.array([a for *_, a, _ in sources.slices], dtype=np.int64),
            reference=reference,
            reference_normals=reference_normals,
            floor=floor,
            floor_G=floor_G,
            stop_anchor=None if config.stop_prior_sigma_m is None else stop_anchor,
        )

    @property
    def floor_sigma(self) -> NDArray[np.float64]:
        """Standard deviations of a floor residual: tilt (2, rad) and offset (m). A sigma left
        to be measured that nobody measured (`pipeline.stages.joint_optimise` measures them) is
        `FALLBACK_FLOOR_SIGMA`'s."""
        tilt_deg = self.config.floor_normal_sigma_deg
        offset_m = self.config.floor_offset_sigma_m
        return np.array(
            [np.radians(FALLBACK_FLOOR_SIGMA[0] if tilt_deg is None else tilt_deg)] * 2
            + [FALLBACK_FLOOR_SIGMA[1] if offset_m is None else offset_m]
        )

    @property
    def stop_sigma(self) -> tuple[float, float]:
        """The stop prior's standard deviations: position (m) and rotation (rad); only where
        the config sets one (`stop_anchor` is not None)."""
        sigma_m = self.config.stop_prior_sigma_m
        if sigma_m is None:
            raise ValueError("optimisation.stop_prior_sigma_m is null: there is no stop prior")
        return sigma_m, float(np.radians(self.config.stop_prior_sigma_deg))

    def place(self, T_G_ref: NDArray[np.float64], T_ref_lidar: NDArray[np.float64]) -> PlacedClouds:
        """Every cloud and its normals mapped by the poses: `T_G_ref` (J, 4, 4) per stop and
        `T_ref_lidar` (L, 4, 4) per LiDAR."""
        sources, reference = self.sources.slices, self.reference.slices
        source_ref = self.sources.transformed([T_ref_lidar[i] for i, *_ in sources])
        source_G = Clouds(source_ref, self.sources.lidar, self.sources.stop, sources).transformed(
            [T_G_ref[j] for _, j, *_ in sources]
        )
        source_poses = [T_G_ref[j] @ T_ref_lidar[i] for i, j, *_ in sources]
        reference_ref = self.reference.transformed([T_ref_lidar[i] for i, *_ in reference])
        reference_G = Clouds(
            reference_ref, self.reference.lidar, self.reference.stop, reference
        ).transformed([T_G_ref[j] for _, j, *_ in reference])
        reference_poses = [T_G_ref[j] @ T_ref_lidar[i] for i, j, *_ in reference]
        return PlacedClouds(
            source_ref,
            source_G,
            self.sources.transformed(source_poses, self.source_normals),
            reference_ref,
            reference_G,
            self.reference.transformed(reference_poses, self.reference_normals),
        )


def _sampled(
    objects: Sequence[Sequence[Points]], config: OptimisationConfig
) -> tuple[list[CloudPart], list[tuple[int, int, NDArray[np.int64]]]]:
    """The non-empty clouds, each cut to a random `max_points_per_cloud` subset (seeded), and the
    rows each kept."""
    rng = np.random.default_rng(config.seed)
    parts: list[CloudPart] = []
    kept: list[tuple[int, int, NDArray[np.int64]]] = []
    for lidar, clouds in enumerate(objects):
        for stop, cloud in enumerate(clouds):
            pts = np.asarray(cloud, dtype=np.float64)
            keep = np.arange(len(pts))
            cap = config.max_points_per_cloud
            if cap is not None and len(pts) > cap:
                keep = np.sort(rng.choice(len(pts), size=cap, replace=False))
            if len(keep):
                parts.append((lidar, stop, pts[keep]))
                kept.append((lidar, stop, keep))
    return parts, kept


def _with_normals(
    parts: list[CloudPart],
    kept: Sequence[tuple[int, int, NDArray[np.int64]]],
    normals: Sequence[Sequence[Points]] | None,
    config: OptimisationConfig,
) -> tuple[list[CloudPart], list[Points]]:
    """The clouds (smoothed onto their local planes when the normals are fitted here and
    `smooth_clouds`) and their normals, facing the sensor."""
    if normals is None:
        # Every cloud is smoothed the same way, as source and as target: an asymmetric
        # treatment (only the reference smoothed) measured a bias of 1-2 cm on range noise.
        surfaces = [local_planes(p, config.normal_neighbours) for *_, p in parts]
        if config.smooth_clouds:
            parts = [(i, j, surface[0]) for (i, j, _), surface in zip(parts, surfaces, strict=True)]
        part_normals = [surface[1] for surface in surfaces]
    else:
        part_normals = [np.asarray(normals[i][j], dtype=np.float64)[keep] for i, j, keep in kept]
    # Normals face their sensor (at each cloud's origin), so that the two sides of a thin
    # object, seen by LiDARs on opposite sides, are told apart by their normals.
    part_normals = [
        orient_towards_origin(p, n) for (*_, p), n in zip(parts, part_normals, strict=True)
    ]
    return parts, part_normals


def _stacked(
    parts: Sequence[CloudPart], part_normals: Sequence[Points], chosen: Sequence[bool]
) -> tuple[Clouds, Points]:
    """The `chosen` clouds concatenated, and their normals (N, 3)."""
    clouds = Clouds.build([p for p, c in zip(parts, chosen, strict=True) if c])
    picked = [n for n, c in zip(part_normals, chosen, strict=True) if c]
    return clouds, np.concatenate(picked) if picked else np.zeros((0, 3))
