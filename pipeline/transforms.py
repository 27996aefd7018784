"""Rigid transforms in SE(3) as 4x4 float64 matrices, named by their frames.

Convention (DESIGN.md): `T_parent_child` maps points from `child` into `parent`,
`p_parent = R @ p_child + t`, the same as a tf edge parent -> child. Quaternions are `[x, y, z, w]`.
Twists, the exp and log maps and planes are in `pipeline.geometry`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

Matrix4 = NDArray[np.float64]
"""A (4, 4) homogeneous rigid transform."""
Points = NDArray[np.float64]
"""An (N, 3) array of points."""


def make_transform(rotation: ArrayLike, translation: ArrayLike) -> Matrix4:
    """Build `T` (4, 4) from a (3, 3) rotation matrix and a (3,) translation."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(rotation, dtype=np.float64)
    T[:3, 3] = np.asarray(translation, dtype=np.float64)
    return T


def from_translation_xyzw(translation: Sequence[float] | ArrayLike, xyzw: ArrayLike) -> Matrix4:
    """Build `T` from a (3,) translation and a (4,) quaternion `[x, y, z, w]` (normalised here)."""
    quat = np.asarray(xyzw, dtype=np.float64)
    with np.errstate(over="ignore"):  # a norm past float64's range is refused just below
        norm = float(np.linalg.norm(quat))
    if not np.isfinite(norm) or norm < 1e-9:
        raise ValueError(
            f"quaternion {quat.tolist()} has no direction; "
            "expected [x, y, z, w] with w or xyz non-zero"
        )
    return make_transform(Rotation.from_quat(quat / norm).as_matrix(), translation)


def to_translation_xyzw(T: Matrix4) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Split `T` into a (3,) translation and a (4,) unit quaternion `[x, y, z, w]` with w >= 0."""
    quat = Rotation.from_matrix(T[:3, :3]).as_quat()
    if quat[3] < 0:
        quat = -quat
    return T[:3, 3].copy(), quat


def from_xyz_rpy(xyz: ArrayLike, rpy: ArrayLike) -> Matrix4:
    """Build `T` from a translation and fixed-axis roll, pitch, yaw in radians (URDF convention)."""
    return make_transform(Rotation.from_euler("xyz", np.asarray(rpy, float)).as_matrix(), xyz)


def invert(T: Matrix4) -> Matrix4:
    """`T_b_a` from `T_a_b`."""
    R = T[:3, :3]
    return make_transform(R.T, -R.T @ T[:3, 3])


def apply(T: Matrix4, points: Points) -> Points:
    """Map (N, 3) points from `T`'s child frame into its parent frame."""
    return np.asarray(points, dtype=np.float64) @ T[:3, :3].T + T[:3, 3]


def rotation_angle_deg(R: NDArray[np.float64]) -> float:
    """The angle in degrees of the rotation `R` (3, 3)."""
    cos = (np.trace(R) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def pose_difference(T_a: Matrix4, T_b: Matrix4) -> tuple[float, float]:
    """Translation distance (m) and rotation angle (deg) between two poses of the same frames."""
    delta = invert(T_a) @ T_b
    return float(np.linalg.norm(T_a[:3, 3] - T_b[:3, 3])), rotation_angle_deg(delta[:3, :3])
