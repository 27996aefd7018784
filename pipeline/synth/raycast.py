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

from pipeline.synth.floor import SINK_M
from pipeline.synth.objects import ObjectRole, SceneObject
from pipeline.synth.scene import Scene

_SUB_RAYS = 6
# Surfaces closer than this along the ray are one return (a box corner, not an edge in front
# of the floor); only a larger spread mixes.
_MIN_GAP_M = 0.1
_FAR_M = 1e6
_STRUCTURES = (ObjectRole.WALL, ObjectRole.SHELF)


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
    ignoring the robot body. Rays in a run with the same origin go to MuJoCo in one batch; an
    analytic floor is hit by `FloorSurface.intersect` and the nearer hit wins."""
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
                scene.ray_groups,
                1,
                scene.robot_body_id,
                geom[start:end],
                dist[start:end],
                normal[start:end].reshape(-1),
                end - start,
                float(max_range),
            )
    hit = (geom >= 0) & (dist >= 0) & (dist <= max_range)
    if scene.floor is not None:
        floor_range, floor_normal = scene.floor.intersect(origins, directions, max_range)
        on_floor = floor_range < np.where(hit, dist, np.inf)
        dist = np.where(on_floor, floor_range, dist)
        geom = np.where(on_floor, scene.object_geom[-1], geom).astype(np.int32)
        normal = np.where(on_floor[:, None], floor_normal, normal)
        hit |= on_floor
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
    """Rays that hit something and whose footprint may touch an object's edge. For objects and
    walkers: the beam's path up to just past its centre hit passes within the object's bounding
    sphere (widened by the footprint's spread). For a room's walls and shelves, whose spheres
    would take in nearly every ray: the footprint covers part of the box but not all of it. A
    ray that reaches the floor before an object cannot straddle that object's edge. Each exact
    test runs on the rays whose segment passes near the object (`segments_near`) only."""
    surfaces = scene.surfaces
    near = np.zeros(len(directions), dtype=bool)
    hit = np.flatnonzero(np.isfinite(range_m))
    origins, directions, range_m = origins[hit], directions[hit], range_m[hit]
    tan_footprint = math.tan(footprint)
    reach = np.minimum(range_m + _MIN_GAP_M, _FAR_M)
    boxes = [obj for obj in surfaces if obj.role in _STRUCTURES]
    if boxes:
        near[hit] = _straddle_boxes(boxes, origins, directions, reach, reach * tan_footprint)
    compact = [obj for obj in surfaces if obj.role not in _STRUCTURES]
    if not compact:
        return near
    centres = np.array([obj.T_world_object[:3, 3] for obj in compact])
    radius = np.array([obj.bounding_radius for obj in compact])
    reach_sphere = range_m + _MIN_GAP_M
    candidates = segments_near(
        centres, radius, origins, directions, reach_sphere, reach_sphere * tan_footprint
    )
    # The exact test on the rows `rows` near some object only.
    in_reach = np.zeros(len(hit), dtype=bool)
    for rows_of_one in candidates:
        in_reach[rows_of_one] = True
    rows = np.flatnonzero(in_reach)
    o, d = origins[rows], directions[rows]
    # Per ray and object: distance along the ray to the centre's foot, and |centre - origin|^2.
    along = d @ centres.T - np.einsum("ij,ij->i", d, o)[:, None]
    to_centre_sq = (
        np.sum(centres**2, axis=1) - 2.0 * o @ centres.T + np.einsum("ij,ij->i", o, o)[:, None]
    )
    for column, rows_of_one in enumerate(candidates):
        at = np.searchsorted(rows, rows_of_one)
        closest = np.clip(along[at, column], 0.0, reach_sphere[rows_of_one])
        distance_sq = to_centre_sq[at, column] - 2.0 * closest * along[at, column] + closest**2
        limit = radius[column] + closest * tan_footprint
        near[hit[rows_of_one]] |= distance_sq <= limit**2
    return near


def _through_box(
    o: NDArray[np.float64],
    d: NDArray[np.float64],
    half: NDArray[np.float64],
    reach: NDArray[np.float64],
    shrink_low: NDArray[np.float64],
    shrink_high: NDArray[np.float64],
) -> NDArray[np.bool_]:
    """Whether each ray (origin `o`, direction `d` (n, 3), in the box's axes) passes, before
    `reach` (n,), through the box of half-sizes `half` (3,) with each face moved inwards by
    `shrink_low` / `shrink_high` (n, 3; negative grows it): the slab test."""
    t_in = np.zeros(len(o))
    t_out = reach.copy()
    solid = np.ones(len(o), dtype=bool)
    for axis in range(3):
        low = -half[axis] + shrink_low[:, axis]
        high = half[axis] - shrink_high[:, axis]
        t1 = (low - o[:, axis]) / d[:, axis]
        t2 = (high - o[:, axis]) / d[:, axis]
        t_in = np.maximum(t_in, np.minimum(t1, t2))
        t_out = np.minimum(t_out, np.maximum(t1, t2))
        solid &= low < high
    return np.asarray(solid & (t_in <= t_out))


def segments_near(
    centres: NDArray[np.float64],
    radius: NDArray[np.float64],
    origins: NDArray[np.float64],
    directions: NDArray[np.float64],
    reach: NDArray[np.float64],
    widen: NDArray[np.float64],
) -> list[NDArray[np.intp]]:
    """Per sphere (`centres` (M, 3), `radius` (M,)), the rays whose segment up to `reach` (N,)
    may pass within its radius plus `widen` (N,) of its centre: a superset, for an exact test
    on those alone. Drawn from the origins' mean, each segment moves by at most the origins'
    spread, which widens the test by as much. `directions` (N, 3) are unit vectors."""
    if len(directions) == 0:
        return [np.zeros(0, dtype=np.intp) for _ in centres]
    mean = origins.mean(axis=0)
    spread = float(np.max(np.linalg.norm(origins - mean, axis=1)))
    # A margin far above rounding and far below any object keeps the superset a superset.
    slack = widen + spread + 1e-6
    found = []
    for centre, r in zip(centres, radius, strict=True):
        offset = centre - mean
        along = directions @ offset
        closest = np.clip(along, 0.0, reach)
        gap_sq = offset @ offset - 2.0 * closest * along + closest**2
        found.append(np.flatnonzero(gap_sq <= (r + slack) ** 2))
    return found


def _straddle_boxes(
    boxes: list[SceneObject],
    origins: NDArray[np.float64],
    directions: NDArray[np.float64],
    reach: NDArray[np.float64],
    spread: NDArray[np.float64],
) -> NDArray[np.bool_]:
    """Rays (N,) whose cylinder of radius `spread` (N,), up to `reach` (N,), meets one of the
    boxes but is not wholly inside it: the ray passes through the box grown by `spread` and
    not through the box shrunk by it (its foot shrunk by `SINK_M` more, where it stands in an
    uneven floor). The cylinder holds every sub-ray of the footprint up to `reach`. Tested
    exactly on the rays `segments_near` each box only."""
    R = np.array([box.T_world_object[:3, :3] for box in boxes])  # (B, 3, 3)
    centres = np.array([box.T_world_object[:3, 3] for box in boxes])
    half = 0.5 * np.array(
        [[b.dimensions["x"], b.dimensions["y"], b.dimensions["z"]] for b in boxes]
    )
    shift = np.einsum("bj,bjk->bk", centres, R)  # each box's centre in its own axes
    straddle = np.zeros(len(origins), dtype=bool)
    near = segments_near(
        centres, np.linalg.norm(half, axis=1), origins, directions, reach, math.sqrt(3.0) * spread
    )
    for box, rows in enumerate(near):
        if len(rows) == 0:
            continue
        # The ray in the box's axes, one axis per column.
        o = origins[rows] @ R[box] - shift[box]
        d = directions[rows] @ R[box]
        d = np.where(np.abs(d) < 1e-12, 1e-12, d)
        grow = spread[rows, None]
        grown = np.broadcast_to(-grow, (len(rows), 3))
        shrunk = np.broadcast_to(grow, (len(rows), 3))
        foot = shrunk + np.array([0.0, 0.0, SINK_M])
        inside = _through_box(o, d, half[box], reach[rows], grown, grown)
        straddle[rows] |= inside & ~_through_box(o, d, half[box], reach[rows], foot, shrunk)
    return straddle


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
