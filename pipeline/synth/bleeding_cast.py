"""Ray casting with a `BleedingModel`'s elliptical beam: sub-rays, mixed and strongest returns.

The counterpart of `raycast.cast_with_footprint` for the randomised beam models of
`pipeline.synth.bleeding`; it shares its ray casting and its test of which rays pass near an
object (the only rays whose footprint can straddle an edge).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.synth.bleeding import BleedingModel
from pipeline.synth.raycast import Returns, _near_objects, cast
from pipeline.synth.scene import Scene

_PARALLEL_COS = 0.999


def cast_with_beam(
    scene: Scene,
    origins: NDArray[np.float64],
    directions: NDArray[np.float64],
    sensor_up: NDArray[np.float64],
    *,
    model: BleedingModel,
    max_range: float,
    label_margin_m: float,
    rng: np.random.Generator,
) -> Returns:
    """Cast rays with `model`'s beam. `origins` (3,) or (N, 3), `directions` (N, 3) and
    `sensor_up` (3,) or (N, 3), the sensor's z axis that the ellipse's orientation is measured
    from, all in the world frame.

    A ray whose centre hits nothing gives no return; one that passes near no object returns its
    centre's hit. The others are sampled by `model.sub_rays` sub-rays inside the ellipse: over one
    surface they return the centre's hit, over two (distinct geoms farther apart than
    `model.min_gap_m`) a mixed return with probability `model.mixed_probability`, else the
    strongest side's. A moved return is attributed to the nearest surface and labelled bleeding
    when it is farther than `label_margin_m` from every surface.
    """
    n = len(directions)
    origins = np.broadcast_to(np.asarray(origins, dtype=np.float64), (n, 3))
    centre = cast(scene, origins, directions, max_range)
    range_m, geom = centre.range_m.copy(), centre.geom.copy()
    is_bleeding = np.zeros(n, dtype=np.bool_)
    spread = model.half_angles_rad[0]
    idx = np.flatnonzero(
        (centre.geom >= 0) & _near_objects(scene, origins, directions, centre.range_m, spread)
    )
    if len(idx) == 0:
        return Returns(range_m, geom, centre.cos_incidence, is_bleeding)
    up = np.broadcast_to(np.asarray(sensor_up, dtype=np.float64), (n, 3))[idx]
    rays = sub_rays(directions[idx], up, model, rng)
    count = model.sub_rays
    sub = cast(scene, np.repeat(origins[idx], count, axis=0), rays.reshape(-1, 3), max_range)
    ranges = sub.range_m.reshape(-1, count)
    geoms = sub.geom.reshape(-1, count)
    energy = np.where(
        geoms >= 0,
        scene.geom_reflectivity[geoms]
        * sub.cos_incidence.reshape(-1, count)
        / np.where(np.isfinite(ranges), ranges, 1.0) ** 2,
        0.0,
    )
    reported = _reported_range(ranges, geoms, energy, model, rng)
    moved = np.isfinite(reported)
    rows = idx[moved]
    if len(rows) == 0:
        return Returns(range_m, geom, centre.cos_incidence, is_bleeding)
    distance, nearest = scene.nearest_surface(
        origins[rows] + directions[rows] * reported[moved, None]
    )
    range_m[rows] = reported[moved]
    geom[rows] = scene.object_geom[nearest]
    is_bleeding[rows] = distance > label_margin_m
    return Returns(range_m, geom, centre.cos_incidence, is_bleeding)


def sub_rays(
    directions: NDArray[np.float64],
    sensor_up: NDArray[np.float64],
    model: BleedingModel,
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    """(N, sub_rays, 3) unit rays drawn uniformly inside each beam's ellipse. The ellipse's
    major axis lies along the sensor's horizontal (perpendicular to the beam and `sensor_up`)
    turned by `model.ellipse_angle_deg` about the beam."""
    up = np.where(
        np.abs(np.einsum("ij,ij->i", directions, sensor_up))[:, None] > _PARALLEL_COS,
        np.array([[1.0, 0.0, 0.0]]),
        sensor_up,
    )
    horizontal = np.cross(up, directions)
    horizontal /= np.linalg.norm(horizontal, axis=1, keepdims=True)
    vertical = np.cross(directions, horizontal)
    turn = np.radians(model.ellipse_angle_deg)
    major_axis = np.cos(turn) * horizontal + np.sin(turn) * vertical
    minor_axis = np.cross(directions, major_axis)
    shape = (len(directions), model.sub_rays)
    radius = np.sqrt(rng.uniform(0.0, 1.0, shape))
    phase = rng.uniform(0.0, 2.0 * np.pi, shape)
    a, b = (np.tan(half) for half in model.half_angles_rad)
    rays = (
        directions[:, None, :]
        + (a * radius * np.cos(phase))[..., None] * major_axis[:, None, :]
        + (b * radius * np.sin(phase))[..., None] * minor_axis[:, None, :]
    )
    return np.asarray(rays / np.linalg.norm(rays, axis=2, keepdims=True))


def _reported_range(
    ranges: NDArray[np.float64],
    geoms: NDArray[np.int32],
    energy: NDArray[np.float64],
    model: BleedingModel,
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    """(N,) the range each beam reports where its sub-rays (N, S) hit two surfaces; inf where
    they do not (the centre ray's hit stands)."""
    hit = geoms >= 0
    fg = np.min(np.where(hit, ranges, np.inf), axis=1)
    bg = np.max(np.where(hit, ranges, -np.inf), axis=1)
    first = np.take_along_axis(geoms, np.argmax(hit, axis=1)[:, None], axis=1)
    two_surfaces = np.any(hit & (geoms != first), axis=1) & (bg - fg > model.min_gap_m)
    mixed = two_surfaces & (rng.uniform(0.0, 1.0, len(ranges)) < model.mixed_probability)
    finite = np.where(hit, ranges, 0.0)
    # A hit whose energy rounds to zero (grazing incidence) still counts in the means.
    energy = energy + 1e-12 * hit
    if model.range_rule == "uniform":
        blended = fg + rng.uniform(0.0, 1.0, len(ranges)) * (bg - fg)
    else:
        blended = _weighted(finite, energy)
    far = hit & (ranges > 0.5 * (fg + bg)[:, None])
    near = hit & ~far
    far_wins = (energy * far).sum(axis=1) > (energy * near).sum(axis=1)
    strongest = np.where(
        far_wins, _weighted(finite, energy * far), _weighted(finite, energy * near)
    )
    return np.where(mixed, blended, np.where(two_surfaces, strongest, np.inf))


def _weighted(values: NDArray[np.float64], weights: NDArray[np.float64]) -> NDArray[np.float64]:
    total = weights.sum(axis=1)
    safe = np.where(total > 0.0, total, 1.0)
    return np.asarray((values * weights).sum(axis=1) / safe, dtype=np.float64)
