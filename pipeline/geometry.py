"""SO(3)/SE(3) algebra, planes and the voxel grid: the geometry every stage shares, in one place.

Twists are `xi = [rho (3), phi (3)]` (translation part first, rotation vector `phi`) and act on
the left of a pose: `T <- exp_se3(xi) @ T`. Frame-named 4x4 transforms (building, inverting,
applying, converting them) live in `pipeline.transforms`; this module adds what the optimisers
need on top of them.

The exp and log maps are written out rather than taken from scipy's `RigidTransform`: both agree
to a few ULP (the tests compare them), but the calibrations' results are pinned bit for bit to
the formulas below.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from pipeline.errors import BadInputError
from pipeline.transforms import Matrix4, Points, make_transform

# -- SO(3) and SE(3) ---------------------------------------------------------------------------


def hat(v: ArrayLike) -> NDArray[np.float64]:
    """The skew matrices (..., 3, 3) of vectors (..., 3): `hat(a) @ b == cross(a, b)`."""
    v = np.asarray(v, dtype=np.float64)
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def adjoint(T: Matrix4) -> NDArray[np.float64]:
    """(6, 6) adjoint of `T` for twists `[rho; phi]`: `exp(Ad(T) xi) = T exp(xi) T^-1`.

    It moves a twist from the child frame of `T` into its parent frame, e.g. a step of an
    extrinsic `T_ref_lidar` expressed as the step of `T_G_ref @ T_ref_lidar` in G.
    """
    R, t = T[:3, :3], T[:3, 3]
    ad = np.zeros((6, 6))
    ad[:3, :3] = R
    ad[:3, 3:] = hat(t) @ R
    ad[3:, 3:] = R
    return ad


def exp_se3(xi: ArrayLike) -> Matrix4:
    """`T` from a twist `xi = [rho (3), phi (3)]` (rotation vector `phi`), SE(3)'s exp map."""
    xi = np.asarray(xi, dtype=np.float64)
    rho, phi = xi[:3], xi[3:]
    theta = float(np.linalg.norm(phi))
    K = hat(phi)
    if theta < 1e-9:
        V = np.eye(3) + 0.5 * K
    else:
        V = (
            np.eye(3)
            + (1 - np.cos(theta)) / theta**2 * K
            + (theta - np.sin(theta)) / theta**3 * (K @ K)
        )
    return make_transform(Rotation.from_rotvec(phi).as_matrix(), V @ rho)


def log_se3(T: Matrix4) -> NDArray[np.float64]:
    """Inverse of `exp_se3`: the twist `[rho, phi]` of `T`."""
    phi = Rotation.from_matrix(T[:3, :3]).as_rotvec()
    theta = float(np.linalg.norm(phi))
    K = hat(phi)
    if theta < 1e-9:
        V_inv = np.eye(3) - 0.5 * K
    else:
        half = theta / 2
        V_inv = np.eye(3) - 0.5 * K + (1 - half / np.tan(half)) / theta**2 * (K @ K)
    return np.concatenate([V_inv @ T[:3, 3], phi])


# -- planes ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Plane:
    """`normal . p + offset = 0` for points `p` on the plane; `normal` (3,) is unit and points up,
    so `offset` > 0 is the height of the frame's origin above the plane."""

    normal: NDArray[np.float64]
    offset: float


def plane_in_parent(plane: Plane, T_parent_child: Matrix4) -> tuple[NDArray[np.float64], float]:
    """A plane of the child frame expressed in the parent frame: (normal (3,), offset)."""
    normal = T_parent_child[:3, :3] @ plane.normal
    return normal, float(plane.offset - normal @ T_parent_child[:3, 3])


def tangent_basis(normal: NDArray[np.float64]) -> NDArray[np.float64]:
    """(3, 2): two unit vectors orthogonal to the unit `normal` and to each other, so that a
    plane's tilt can be measured in two numbers (the normal's change along them)."""
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    first = np.cross(normal, helper)
    first /= np.linalg.norm(first)
    return np.stack([first, np.cross(normal, first)], axis=1)


# -- the voxel grid ----------------------------------------------------------------------------

_HALF_RANGE = 1 << 20
"""21 bits per axis, centred on the origin: +-20 km at 2 cm cells."""


def pack_cells(cells: NDArray[np.int64]) -> NDArray[np.int64]:
    """(..., 3) integer cell coordinates -> (...,) one int64 each, 21 bits per axis.

    Packed keys add like the vectors they pack as long as no field over- or underflows, so a
    neighbour's key is a key plus a packed offset (negative offsets included).
    """
    packed: NDArray[np.int64] = (cells[..., 0] << 42) + (cells[..., 1] << 21) + cells[..., 2]
    return packed


def voxel_keys(points: Points, cell_size: float, setting: str) -> NDArray[np.int64]:
    """(N,) the packed key of each point's cubic cell of edge `cell_size` (metres).

    The grid keeps one cell of margin at each end, so the key of any point's 26 neighbour cells
    is `key + pack_cells(offset)` without wrapping into another axis. A point beyond the grid
    raises `BadInputError` naming `setting`, the configuration value that sets `cell_size`.
    Packing avoids the min/max passes a dense index would need.
    """
    if len(points) and np.abs(points).max() / cell_size >= _HALF_RANGE - 1:
        raise BadInputError(
            f"points up to {np.abs(points).max():.0f} m from the sensor do not fit the voxel grid "
            f"of {cell_size} m; use a larger {setting} or crop the clouds"
        )
    cells = np.floor(points * (1.0 / cell_size)).astype(np.int64) + _HALF_RANGE
    return pack_cells(cells)
