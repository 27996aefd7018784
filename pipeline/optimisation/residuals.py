"""Residuals and Jacobians of the joint optimisation, and its robust cost.

Point residuals: source point minus its target point in G (point-to-point, 3 rows), or that
difference along the target's normal (point-to-plane, 1 row). Their Jacobians have 24 columns:
the left twists of the four poses a pair involves, in the order (source stop `T_G_ref[j]`,
source LiDAR `T_ref_lidar[i]`, target stop `T_G_ref[k]`, target LiDAR `T_ref_lidar[t]`);
`assembly` folds them into the state vector.

Floor residuals: every observed floor plane, mapped into G, against the floor from stage 3:
tilt (2, in the floor's tangent basis) and offset (1), whitened by their sigmas.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.geometry import adjoint, hat, plane_in_parent, tangent_basis
from pipeline.optimisation.association import Pairs
from pipeline.optimisation.config import ResidualKind, RobustLoss
from pipeline.optimisation.objective import JointObjective, PlacedClouds
from pipeline.optimisation.stop_prior import stop_prior_terms
from pipeline.transforms import Points


def robust_weight_and_cost(
    distance: NDArray[np.float64], scale: float, loss: RobustLoss
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """IRLS weight w(s) = rho'(s)/s and cost rho(s) for distances `s` (N,); rho(s) ~ s^2/2 at 0."""
    if loss == "cauchy":
        ratio = (distance / scale) ** 2
        return 1.0 / (1.0 + ratio), 0.5 * scale**2 * np.log1p(ratio)
    if loss == "geman_mcclure":
        ratio = (distance / scale) ** 2
        return 1.0 / (1.0 + ratio) ** 2, 0.5 * scale**2 * ratio / (1.0 + ratio)
    if loss == "huber":
        inside = distance <= scale
        weight = np.where(inside, 1.0, scale / np.maximum(distance, 1e-300))
        cost = np.where(inside, 0.5 * distance**2, scale * (distance - 0.5 * scale))
        return weight, cost
    return np.ones_like(distance), 0.5 * distance**2


def pair_weights_and_costs(
    objective: JointObjective, pairs: Pairs, residual: NDArray[np.float64], scale: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Each pair's IRLS weight (1/m^2) and robust cost (whitened: the cost's units) for its
    `residual` (n, rows). Where `pairs.sigma` is measured, each residual is first rescaled so
    that its sigma reads `point_sigma_m`: a pair of sigma s weighs 1/s^2 near zero and leaves
    the robust kernel at `scale` s / `point_sigma_m`."""
    config = objective.config
    unit = config.point_sigma_m
    ratio = 1.0 if pairs.sigma is None else unit / pairs.sigma
    distance = np.linalg.norm(residual, axis=1) * ratio
    weight, cost = robust_weight_and_cost(distance, scale, config.robust_loss)
    return weight * ratio**2 / unit**2, cost / unit**2


def whitened_residuals(
    pairs: Pairs, residual: NDArray[np.float64], unit: float
) -> NDArray[np.float64]:
    """`residual` (n, rows) rescaled so that each pair's sigma reads `unit` (as they are where
    `pairs.sigma` is None)."""
    if pairs.sigma is None:
        return residual
    result: NDArray[np.float64] = residual * (unit / pairs.sigma)[:, None]
    return result


_CHI3_MEDIAN = 1.5382
"""Median of the norm of a 3-D standard normal vector (chi with 3 degrees of freedom)."""


def robust_sigma(residuals: NDArray[np.float64]) -> float:
    """The standard deviation of one component of `residuals` (n, 1) or (n, 3), from the median
    of their norms, so outliers up to half of them do not inflate it: 1.4826 x the median
    absolute value in 1-D, the median norm / 1.5382 in 3-D. NaN when there are none."""
    if len(residuals) == 0:
        return float("nan")
    norms = np.linalg.norm(residuals, axis=1)
    median = float(np.median(norms))
    return 1.4826 * median if residuals.shape[1] == 1 else median / _CHI3_MEDIAN


def _cross(a: Points, b: Points) -> Points:
    """Row-wise cross product of (N, 3) arrays; `np.cross` spends more on axis bookkeeping."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def point_residuals(kind: ResidualKind, pairs: Pairs, placed: PlacedClouds) -> NDArray[np.float64]:
    """(n, 3) point-to-point or (n, 1) point-to-plane residuals, metres."""
    difference = placed.source_G[pairs.source] - placed.reference_G[pairs.target]
    if kind == "point_to_plane":
        normals = placed.normals_G[pairs.target]
        result: NDArray[np.float64] = np.einsum("ni,ni->n", normals, difference)[:, None]
        return result
    return difference


def point_jacobians(
    objective: JointObjective,
    pairs: Pairs,
    placed: PlacedClouds,
    T_G_ref: NDArray[np.float64],
) -> NDArray[np.float64]:
    """(n, rows, 24) derivatives of `point_residuals` by the four poses' twists (see module)."""
    src, tgt = pairs.source, pairs.target
    g, q, m = placed.source_G[src], placed.source_ref[src], placed.reference_G[tgt]
    q_target = placed.reference_ref[tgt]
    R_stop = T_G_ref[objective.sources.stop[src]][:, :3, :3]
    R_target = T_G_ref[objective.reference.stop[tgt]][:, :3, :3]
    n = len(src)
    if objective.config.residual == "point_to_plane":
        jac = np.empty((n, 1, 24))
        n_G = placed.normals_G[tgt]
        n_ref = np.einsum("nji,nj->ni", R_stop, n_G)  # the normal in the reference frame
        jac[:, 0, 0:3] = n_G
        jac[:, 0, 3:6] = _cross(g, n_G)
        jac[:, 0, 6:9] = n_ref
        jac[:, 0, 9:12] = _cross(q, n_ref)
        jac[:, 0, 12:15] = -n_G
        # The target's normal turns with its stop too: d(n.(g - m))/d(phi_k).
        jac[:, 0, 15:18] = -_cross(m, n_G) + _cross(n_G, g - m)
        # ...and with its LiDAR's extrinsics (in the reference frame of its stop).
        u = np.einsum("nji,nj->ni", R_target, n_G)
        w = np.einsum("nji,nj->ni", R_target, g - m)
        jac[:, 0, 18:21] = -u
        jac[:, 0, 21:24] = _cross(u, q_target + w)
        return jac
    jac = np.empty((n, 3, 24))
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    jac[:, :, 0:3] = eye
    jac[:, :, 3:6] = -hat(g)
    jac[:, :, 6:9] = R_stop
    jac[:, :, 9:12] = -R_stop @ hat(q)
    jac[:, :, 12:15] = -eye
    jac[:, :, 15:18] = hat(m)
    jac[:, :, 18:21] = -R_target
    jac[:, :, 21:24] = R_target @ hat(q_target)
    return jac


def floor_terms(
    objective: JointObjective,
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
    *,
    jacobians: bool,
    ideal: bool = False,
    stop: int | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Whitened floor residuals (K, 3) and, if asked, their Jacobians (K, 3, P), of every
    floor observation (in `objective.floor`'s order) or of one `stop`'s alone.

    `ideal`: linearise at the common floor instead of at each observed plane. The exact
    Jacobian gives a turn about the floor normal a little leverage through each plane's
    residual tilt, which would make a bare floor look as if it fixed the yaw.
    """
    assert objective.floor_G is not None
    normal_G, offset_G = objective.floor_G.normal, objective.floor_G.offset
    tangent = tangent_basis(normal_G)
    observed = [term for term in objective.floor if stop is None or term[1] == stop]
    residual = np.empty((len(observed), 3))
    jac = np.zeros((len(observed), 3, objective.layout.size if jacobians else 0))
    for row, (lidar, seen_at, plane) in enumerate(observed):
        normal, offset = plane_in_parent(plane, T_G_ref[seen_at] @ T_ref_lidar[lidar])
        residual[row, :2] = tangent.T @ (normal - normal_G)
        residual[row, 2] = offset - offset_G
        if jacobians:
            at = normal_G if ideal else normal
            _fill_floor_jacobian(jac[row], objective, lidar, seen_at, at, T_G_ref, ideal, tangent)
    sigma = objective.floor_sigma
    return residual / sigma, jac / sigma[None, :, None]


def _fill_floor_jacobian(
    jac: NDArray[np.float64],
    objective: JointObjective,
    lidar: int,
    stop: int,
    at: NDArray[np.float64],
    T_G_ref: NDArray[np.float64],
    ideal: bool,
    tangent: NDArray[np.float64],
) -> None:
    """Write into `jac` (3, P) one floor observation's derivatives, linearised at the normal
    `at` in G (the observed plane's, or under `ideal` the common floor's); `tangent` (3, 2) is
    the common floor's `tangent_basis`, which the caller computes once for every observation."""
    assert objective.floor_G is not None
    normal_G = objective.floor_G.normal
    d_twist = np.zeros((3, 6))
    d_twist[:2, 3:] = -tangent.T @ hat(at)
    d_twist[2, :3] = -at
    layout = objective.layout
    if (col := layout.stop(stop)) >= 0:
        jac[:, col : col + 6] = d_twist
    if (col := layout.lidar(lidar)) < 0:
        return
    if not ideal:
        jac[:, col : col + 6] = d_twist @ adjoint(T_G_ref[stop])
        return
    # The same derivative with the plane taken as the floor itself in the reference
    # frame (the robot stands on the floor at every stop).
    R_stop, t_stop = T_G_ref[stop][:3, :3], T_G_ref[stop][:3, 3]
    floor_ref = T_G_ref[0][:3, :3].T @ normal_G
    jac[:2, col + 3 : col + 6] = -(tangent.T @ R_stop) @ hat(floor_ref)
    jac[2, col : col + 3] = -floor_ref
    jac[2, col + 3 : col + 6] = -_cross(floor_ref, R_stop.T @ t_stop)


def cost(
    objective: JointObjective,
    pairs: Pairs,
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
    scale: float,
    placed: PlacedClouds | None = None,
) -> float:
    """The robust cost with these poses and fixed pairs: point terms (weights in 1/sigma^2) and
    half the whitened floor residuals' squares. `placed`: the clouds already placed with these
    poses, where the caller has them."""
    config = objective.config
    if placed is None:
        placed = objective.place(T_G_ref, T_ref_lidar)
    residual = point_residuals(config.residual, pairs, placed)
    _, point_cost = pair_weights_and_costs(objective, pairs, residual, scale)
    floor_cost = 0.0
    if objective.floor:
        floor_residual, _ = floor_terms(objective, T_G_ref, T_ref_lidar, jacobians=False)
        floor_cost = 0.5 * float(np.sum(floor_residual**2))
    prior_cost = 0.0
    if objective.stop_anchor is not None:
        prior_residual, _ = stop_prior_terms(
            objective.stop_anchor, T_G_ref, objective.stop_sigma, jacobians=False
        )
        prior_cost = 0.5 * float(np.sum(prior_residual**2))
    return float(np.sum(point_cost)) + floor_cost + prior_cost
