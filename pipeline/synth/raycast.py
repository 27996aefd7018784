"""Ray casting with MuJoCo's batched `mj_multiRay`, and mixed returns at depth discontinuities.

A real beam has a footprint, not a line. Where the footprint straddles an object's edge and the
background behind it, the receiver gets one pulse mixed from both surfaces and reports a range in
between: a *bleeding point* floating in free space. We model the footprint by sub-rays on a ring
of half-angle `footprint_deg` round each ray.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from pipeline.synth.scene import Scene

_SUB_RAYS = 6
# Surfaces closer than this along the ray are one return (a box corner, not an edge in front
# of the floor); only a larger spread mixes.
_MIN_GAP_M = 0.1


@dataclass(frozen=True)
class Hits:
    """Per ray: `range_m` (N,) float64 (inf for a miss), `geom` (N,) int32 (-1 for a miss),
    `cos_incidence` (N,) float64 (|cos| between ray and surface normal, 0 for a miss)."""

    range_m: NDArray[np.float64]
    geom: NDArray[np.int32]
    cos_incidence: NDArray[np.float64]


def cast(
    scene: Scene, origins: NDArray[np.float64], directions: NDArray[np.float64], max_range: float
) -> Hits:
    """Cast (N, 3) unit `directions` (world frame) from `origins` ((3,), or (N, 3) per ray),
    ignoring the robot body. Rays in a run with the same origin go to MuJoCo in one batch."""
    n = len(directions)
    origins = np.broadcast_to(np.asarray(origins, dtype=np.float64), (n, 3))
    geom = np.empty(n, dtype=np.int32)
    dist = np.empty(n, dtype=np.float64)
    normal = np.empty((n, 3), dtype=np.float64)
    flat = np.ascontiguousarray(directions, dtype=np.float64)
    starts = np.concatenate(
        [[0], np.flatnonzero(np.any(np.diff(origins, axis=0) != 0, axis=1)) + 1]
    )
    for start, end in zip(starts.tolist(), [*starts[1:].tolist(), n], strict=True):
        if end > start:
            mujoco.mj_multiRay(
                scene.model,
                scene.data,
                np.ascontiguousarray(origins[start]),
                flat[start:end].reshape(-1),
                None,
                1,
                scene.robot_body_id,
                geom[start:end],
                dist[start:end],
                normal[start:end].reshape(-1),
                end - start,
                float(max_range),
            )
    hit = (geom >= 0) & (dist >= 0) & (dist <= max_range)
    cos_incidence = np.abs(np.einsum("ij,ij->i", normal, directions))
    return Hits(
        range_m=np.where(hit, dist, np.inf),
        geom=np.where(hit, geom, -1).astype(np.int32),
        cos_incidence=np.where(hit, cos_incidence, 0.0),
    )


@dataclass(frozen=True)
class Returns:
    """What the receiver reports per ray: `range_m` (inf: no return), the surface `geom` it is
    attributed to (the nearest one), `cos_incidence`, and `is_bleeding`: the range was blended
    across an edge and the point lies farther than the label margin from every surface."""

    range_m: NDArray[np.float64]
    geom: NDArray[np.int32]
    cos_incidence: NDArray[np.float64]
    is_bleeding: NDArray[np.bool_]


def cast_with_footprint(
    scene: Scene,
    origins: NDArray[np.float64],
    directions: NDArray[np.float64],
    *,
    max_range: float,
    footprint_deg: float,
    label_margin_m: float,
    rng: np.random.Generator,
) -> Returns:
    """Cast rays and blend the returns of those whose footprint crosses a depth discontinuity.

    Sub-rays are cast only for rays that pass near an object (its bounding sphere widened by the
    footprint): the floor alone has no discontinuity, so elsewhere the centre ray is the answer.
    A blended range is `fg + w * (bg - fg)` between the nearest and farthest surface in the
    footprint, `w ~ Beta` centred on the share of the footprint on the far surface. A sub-ray
    that misses everything adds no energy, so an edge against empty space does not bleed.
    `origins` is (3,) or (N, 3) per ray, as for `cast`.
    """
    origins = np.broadcast_to(np.asarray(origins, dtype=np.float64), directions.shape)
    centre = cast(scene, origins, directions, max_range)
    range_m = centre.range_m.copy()
    geom = centre.geom.copy()
    is_bleeding = np.zeros(len(directions), dtype=bool)
    footprint = math.radians(footprint_deg)
    hit = centre.geom >= 0
    near = hit & _near_objects(scene, origins, directions, centre.range_m, footprint)
    idx = np.flatnonzero(near)
    if footprint <= 0 or len(idx) == 0:
        return Returns(range_m, geom, centre.cos_incidence, is_bleeding)

    sub_dirs = _footprint_rays(directions[idx], footprint)
    sub = cast(
        scene, np.repeat(origins[idx], _SUB_RAYS, axis=0), sub_dirs.reshape(-1, 3), max_range
    )
    ranges = np.column_stack([centre.range_m[idx], sub.range_m.reshape(len(idx), _SUB_RAYS)])
    geoms = np.column_stack([centre.geom[idx], sub.geom.reshape(len(idx), _SUB_RAYS)])
    hit = geoms >= 0
    fg = np.min(np.where(hit, ranges, np.inf), axis=1)
    bg = np.max(np.where(hit, ranges, -np.inf), axis=1)
    other_surface = np.any(hit & (geoms != geoms[:, :1]), axis=1)
    mixed = other_surface & (bg - fg > _MIN_GAP_M)
    if not mixed.any():
        return Returns(range_m, geom, centre.cos_incidence, is_bleeding)

    ranges, geoms, hit, fg, bg = ranges[mixed], geoms[mixed], hit[mixed], fg[mixed], bg[mixed]
    far = hit & (ranges > 0.5 * (fg + bg)[:, None])
    far_share = far.sum(axis=1) / hit.sum(axis=1)
    weight = rng.beta(1.0 + 3.0 * far_share, 1.0 + 3.0 * (1.0 - far_share))
    blended = fg + weight * (bg - fg)
    rows = idx[mixed]
    distance, nearest = scene.nearest_surface(origins[rows] + directions[rows] * blended[:, None])
    range_m[rows] = blended
    geom[rows] = scene.object_geom[nearest]
    is_bleeding[rows] = distance > label_margin_m
    return Returns(range_m, geom, centre.cos_incidence, is_bleeding)


def _near_objects(
    scene: Scene,
    origins: NDArray[np.float64],
    directions: NDArray[np.float64],
    range_m: NDArray[np.float64],
    footprint: float,
) -> NDArray[np.bool_]:
    """Rays whose footprint may touch an object: the beam's path up to just past its centre hit
    passes within the object's bounding sphere (widened by the footprint's spread). A ray that
    reaches the floor before an object cannot straddle that object's edge."""
    if not scene.objects:
        return np.zeros(len(directions), dtype=bool)
    centres = np.array([obj.T_world_object[:3, 3] for obj in scene.objects])
    radius = np.array([obj.bounding_radius for obj in scene.objects])
    # Per ray and object: distance along the ray to the centre's foot, and |centre - origin|^2.
    along = directions @ centres.T - np.einsum("ij,ij->i", directions, origins)[:, None]
    to_centre_sq = (
        np.sum(centres**2, axis=1)
        - 2.0 * origins @ centres.T
        + np.einsum("ij,ij->i", origins, origins)[:, None]
    )
    reach = np.minimum(range_m + _MIN_GAP_M, np.finfo(np.float64).max)[:, None]
    closest = np.clip(along, 0.0, reach)
    distance_sq = to_centre_sq - 2.0 * closest * along + closest**2
    limit = radius + closest * math.tan(footprint)
    return np.asarray(np.any(distance_sq <= limit**2, axis=1))


def _footprint_rays(directions: NDArray[np.float64], footprint: float) -> NDArray[np.float64]:
    """(N, SUB_RAYS, 3) unit rays on a cone of half-angle `footprint` round each direction."""
    helper = np.where(np.abs(directions[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(directions, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(directions, u)
    phase = 2.0 * math.pi * np.arange(_SUB_RAYS) / _SUB_RAYS
    ring = (
        np.cos(phase)[None, :, None] * u[:, None, :] + np.sin(phase)[None, :, None] * v[:, None, :]
    )
    rays = math.cos(footprint) * directions[:, None, :] + math.sin(footprint) * ring
    return np.asarray(rays / np.linalg.norm(rays, axis=2, keepdims=True))
