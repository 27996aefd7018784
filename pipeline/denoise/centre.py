"""The observation centre of a scan: where its pattern is centred on the observed floor."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.denoise.filters import Points, as_cloud
from pipeline.errors import BadInputError

# An axis within ~0.6 deg of the floor meets it far beyond the scene, or never.
_MIN_AXIS_FLOOR_COS = 1e-2
_RANSAC_SAMPLE = 4096


def observation_centre(
    points: ArrayLike,
    optical_axis: Sequence[float] | ArrayLike,
    floor_plane: ArrayLike | None = None,
    *,
    floor_distance_m: float = 0.05,
    floor_iterations: int = 200,
    seed: int = 0,
) -> Points:
    """Where the scan pattern is centred on the observed scene, (3,) in the LiDAR frame.

    The paper leaves this open. Ours: the point where the optical axis (a ray from the sensor at
    the origin along `optical_axis`) meets the floor plane, because a LiDAR tilted towards the
    travel surface centres its pattern there. The floor is `floor_plane` `[a, b, c, d]`
    (`a x + b y + c z + d = 0`) when given, else the largest plane of the cloud by RANSAC
    (`floor_distance_m` inlier distance). When the axis misses the floor (parallel to it, pointing
    away from it, or meeting it beyond the farthest measured point) the centre is the cloud point
    closest to the axis ray instead: the first thing the axis sees.
    """
    cloud = as_cloud(points)
    axis = np.asarray(optical_axis, dtype=np.float64).reshape(-1)
    norm = float(np.linalg.norm(axis)) if axis.shape == (3,) else 0.0
    if not np.isfinite(norm) or norm < 1e-12:
        raise BadInputError(f"the optical axis must be a non-zero (3,) vector; got {axis.tolist()}")
    axis = axis / norm
    if len(cloud) == 0:
        raise BadInputError("an empty cloud has no observation centre")
    plane = (
        np.asarray(floor_plane, dtype=np.float64).reshape(4)
        if floor_plane is not None
        else fit_floor_plane(cloud, floor_distance_m, floor_iterations, seed)
    )
    if plane is not None:
        hit = _axis_meets_plane(axis, plane, float(np.linalg.norm(cloud, axis=1).max()))
        if hit is not None:
            return hit
    along = np.clip(cloud @ axis, 0.0, None)
    off_axis = np.linalg.norm(cloud - along[:, None] * axis, axis=1)
    return np.array(cloud[int(np.argmin(off_axis))], dtype=np.float64)


def _axis_meets_plane(axis: Points, plane: Points, max_range: float) -> Points | None:
    normal, offset = plane[:3], plane[3]
    scale = float(np.linalg.norm(normal))
    if scale < 1e-12:
        return None
    cos_angle = float(normal @ axis) / scale
    if abs(cos_angle) < _MIN_AXIS_FLOOR_COS:
        return None
    t = -offset / scale / cos_angle
    if t <= 0.0 or t > max_range:
        return None
    return np.asarray(t * axis, dtype=np.float64)


def fit_floor_plane(
    cloud: Points, distance_m: float = 0.05, iterations: int = 200, seed: int = 0
) -> NDArray[np.float64] | None:
    """The largest plane of an (N, 3) cloud, `[a, b, c, d]` with unit normal, or None if none.

    Vectorised RANSAC: all hypotheses are scored at once on a subsample, the best is refitted by
    least squares on its inliers in the whole cloud. Deterministic for a given `seed`.
    """
    if len(cloud) < 3:
        return None
    rng = np.random.default_rng(seed)
    triples = cloud[rng.integers(0, len(cloud), size=(iterations, 3))]
    normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    lengths = np.linalg.norm(normals, axis=1)
    valid = lengths > 1e-12
    if not valid.any():
        return None
    normals = normals[valid] / lengths[valid, None]
    offsets = -np.einsum("ij,ij->i", normals, triples[valid, 0])
    sample = cloud[rng.choice(len(cloud), size=min(len(cloud), _RANSAC_SAMPLE), replace=False)]
    inlier_counts = (np.abs(sample @ normals.T + offsets) < distance_m).sum(axis=0)
    best = int(np.argmax(inlier_counts))
    inliers = cloud[np.abs(cloud @ normals[best] + offsets[best]) < distance_m]
    if len(inliers) < 3:
        return np.append(normals[best], offsets[best])
    centroid = inliers.mean(axis=0)
    normal = np.linalg.svd(inliers - centroid, full_matrices=False)[2][2]
    return np.append(normal, -normal @ centroid)
