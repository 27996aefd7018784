"""The stop poses' prior: each stop's pose in G held, softly, where stage 4 started it.

Why: a stop whose object points pair with nothing (or with a handful) leaves directions of its
pose that the data do not fix. Without a prior the solve divides rounding noise along them and
throws the stop by tenths of a metre a step, and stage 4 ends on its iteration limit while the
extrinsics have long settled (bench_random seed 1028). The prior is an odometry-like belief: a
stop is where the start put it, within `stop_prior_sigma_m` and `stop_prior_sigma_deg`; against
the information of a stop the objects hold (1e4-1e7 per m^2) it weighs nothing.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from pipeline.geometry import hat


def stop_prior_terms(
    anchor_G_ref: NDArray[np.float64],
    T_G_ref: NDArray[np.float64],
    sigma: tuple[float, float],
    *,
    jacobians: bool = True,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Whitened residuals (J - 1, 6) of every free stop's pose `T_G_ref[j]` (j >= 1) against
    `anchor_G_ref[j]`: position difference in G (m) and rotation vector of `R_j R_anchor_j^T`
    (rad), over `sigma` = (m, rad); and each one's Jacobian by that stop's own left twist
    `[rho, phi]` (J - 1, 6, 6), the only pose it depends on (empty without `jacobians`)."""
    n = len(T_G_ref) - 1
    residual = np.zeros((n, 6))
    jac = np.zeros((n if jacobians else 0, 6, 6))
    for row, j in enumerate(range(1, len(T_G_ref))):
        R, p = T_G_ref[j][:3, :3], T_G_ref[j][:3, 3]
        turn = Rotation.from_matrix(R @ anchor_G_ref[j][:3, :3].T).as_rotvec()
        residual[row, :3] = (p - anchor_G_ref[j][:3, 3]) / sigma[0]
        residual[row, 3:] = turn / sigma[1]
        if jacobians:
            # A left twist [rho, phi] moves p to p + phi x p + rho and turns R by phi.
            jac[row, :3, :3] = np.eye(3) / sigma[0]
            jac[row, :3, 3:] = -hat(p) / sigma[0]
            jac[row, 3:, 3:] = _left_jacobian_inverse(turn) / sigma[1]
    return residual, jac


def _left_jacobian_inverse(phi: NDArray[np.float64]) -> NDArray[np.float64]:
    """(3, 3) SO(3)'s inverse left Jacobian at the rotation vector `phi`: how `phi` changes
    under a small rotation applied on the left."""
    theta = float(np.linalg.norm(phi))
    K = hat(phi)
    if theta < 1e-6:
        return np.eye(3) - 0.5 * K
    factor = 1.0 / theta**2 - (1.0 + np.cos(theta)) / (2.0 * theta * np.sin(theta))
    result: NDArray[np.float64] = np.eye(3) - 0.5 * K + factor * (K @ K)
    return result
