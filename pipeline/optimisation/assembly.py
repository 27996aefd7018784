"""Assembly: the normal equations `H = J^T W J`, `b = J^T W r` of the joint optimisation, from
the point pairs' 24-column Jacobians and the floor terms, in the state vector's layout."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.geometry import voxel_keys
from pipeline.optimisation.association import Pairs
from pipeline.optimisation.objective import JointObjective, PlacedClouds
from pipeline.optimisation.residuals import (
    floor_terms,
    pair_weights_and_costs,
    point_jacobians,
    point_residuals,
)
from pipeline.optimisation.stop_prior import stop_prior_terms

NormalEquations = tuple[NDArray[np.float64], NDArray[np.float64], float, int]
"""`(H (P, P), b (P,), weighted squared residual sum, number of residual rows)`."""


def normal_equations(
    objective: JointObjective,
    pairs: Pairs,
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
    scale: float,
    *,
    ideal_floor: bool = False,
    floor_stop: int | None = None,
    with_floor: bool = True,
    placed: PlacedClouds | None = None,
) -> NormalEquations:
    """H = J^T W J, b = J^T W r (weights in 1/sigma^2), the weighted squared residual sum
    and the number of residual rows. `ideal_floor`: see `residuals.floor_terms`; `floor_stop`:
    only that stop's floor terms (None: every stop's); `with_floor` False: the point pairs alone.
    `placed`: the clouds already placed with these poses, where the caller has them."""
    layout = objective.layout
    H = np.zeros((layout.size, layout.size))
    b = np.zeros(layout.size)
    if placed is None:
        placed = objective.place(T_G_ref, T_ref_lidar)
    sorted_pairs, key = _grouped(objective, pairs)
    residual = point_residuals(objective.config.residual, sorted_pairs, placed)
    weight, _ = pair_weights_and_costs(objective, sorted_pairs, residual, scale)
    jac = point_jacobians(objective, sorted_pairs, placed, T_G_ref)
    _add_point_groups(H, b, objective, key, jac, weight, residual)
    chi2 = float(np.sum(weight[:, None] * residual**2))
    count = residual.size
    if objective.floor and with_floor:
        floor_residual, floor_jac = floor_terms(
            objective, T_G_ref, T_ref_lidar, jacobians=True, ideal=ideal_floor, stop=floor_stop
        )
        H += np.einsum("kri,krj->ij", floor_jac, floor_jac)
        b += np.einsum("kri,kr->i", floor_jac, floor_residual)
        chi2 += float(np.sum(floor_residual**2))
        count += floor_residual.size
    if objective.stop_anchor is not None and with_floor and floor_stop is None:
        prior_residual, prior_jac = stop_prior_terms(
            objective.stop_anchor, T_G_ref, objective.stop_sigma
        )
        for j in range(1, layout.n_stops):
            c = layout.stop(j)
            H[c : c + 6, c : c + 6] += prior_jac[j - 1].T @ prior_jac[j - 1]
            b[c : c + 6] += prior_jac[j - 1].T @ prior_residual[j - 1]
    return H, b, chi2, count


def _grouped(objective: JointObjective, pairs: Pairs) -> tuple[Pairs, NDArray[np.int64]]:
    """The pairs sorted by group (source cloud, target stop, target LiDAR), and each one's key:
    within a group the four poses involved are the same, so one small GEMM gives the group's
    contribution."""
    layout = objective.layout
    slice_of = np.searchsorted(objective.source_starts, pairs.source, side="right") - 1
    target_stop = objective.reference.stop[pairs.target]
    target_lidar = objective.reference.lidar[pairs.target]
    key = (slice_of * layout.n_stops + target_stop) * layout.n_lidars + target_lidar
    order = np.argsort(key, kind="stable")
    return pairs.take(order), key[order]


def _add_point_groups(
    H: NDArray[np.float64],
    b: NDArray[np.float64],
    objective: JointObjective,
    key: NDArray[np.int64],
    jac: NDArray[np.float64],
    weight: NDArray[np.float64],
    residual: NDArray[np.float64],
) -> None:
    """Add to `H` and `b` (in place) every group's rows of the pairs sorted by `key`."""
    layout = objective.layout
    n = len(key)
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]]) if n else np.zeros(0, np.int64)
    ends = np.r_[starts[1:], n] if n else starts
    for a, b_end in zip(starts, ends, strict=True):
        group = int(key[a])
        t = group % layout.n_lidars
        k = (group // layout.n_lidars) % layout.n_stops
        lidar, j, *_ = objective.sources.slices[group // layout.n_lidars // layout.n_stops]
        # Slots (S_j, C_i, S_k, C_t); a pose in two slots (the same stop, or a LiDAR's own
        # map) gets the sum of their blocks, a fixed pose none.
        slots: dict[int, list[int]] = {}
        for slot, column in enumerate(
            (layout.stop(j), layout.lidar(lidar), layout.stop(k), layout.lidar(t))
        ):
            if column >= 0:
                slots.setdefault(column, []).append(slot)
        if not slots:
            continue
        block = np.concatenate([_slot_sum(jac[a:b_end], x) for x in slots.values()], axis=2)
        wblock = block * weight[a:b_end, None, None]
        cols = np.concatenate([np.arange(c, c + 6) for c in slots])
        flat = block.reshape(-1, block.shape[2])
        wflat = wblock.reshape(-1, block.shape[2])
        H[np.ix_(cols, cols)] += wflat.T @ flat
        b[cols] += wflat.T @ residual[a:b_end].reshape(-1)


def _slot_sum(jac: NDArray[np.float64], slots: list[int]) -> NDArray[np.float64]:
    """The sum of the 6-column blocks `slots` of the rows `jac` (n, r, 24): one pose's columns
    where it fills several slots of a pair; a view where it fills one."""
    first = jac[:, :, 6 * slots[0] : 6 * slots[0] + 6]
    if len(slots) == 1:
        return first
    total = first.copy()
    for slot in slots[1:]:
        total += jac[:, :, 6 * slot : 6 * slot + 6]
    return total


def stop_contributions(
    objective: JointObjective,
    pairs: Pairs,
    stops: NDArray[np.float64],
    lidars: NDArray[np.float64],
    scale: float,
    placed: PlacedClouds | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per stop, the information (J, P, P) and gradient (J, P) of the residuals that touch it.

    A pair touches stop j when its source or its target point was seen there; a pair between two
    stops counts for both, as leaving either out removes it. `placed`: the clouds placed with
    these poses, where the caller has them.
    """
    layout = objective.layout
    if placed is None:
        placed = objective.place(stops, lidars)
    H = np.zeros((layout.n_stops, layout.size, layout.size))
    b = np.zeros((layout.n_stops, layout.size))
    source_stop = objective.sources.stop[pairs.source]
    target_stop = objective.reference.stop[pairs.target]
    for j in range(layout.n_stops):
        touching = (source_stop == j) | (target_stop == j)
        if not touching.any() and not any(stop == j for _, stop, _ in objective.floor):
            continue
        subset = pairs.take(touching)
        H[j], b[j], _, _ = normal_equations(
            objective, subset, stops, lidars, scale, ideal_floor=True, floor_stop=j, placed=placed
        )
    return H, b


def block_contributions(
    objective: JointObjective,
    pairs: Pairs,
    stops: NDArray[np.float64],
    lidars: NDArray[np.float64],
    scale: float,
    block_m: float,
    placed: PlacedClouds | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per block of space, the information (B, P, P) and gradient (B, P) of the point pairs
    whose target lies in it: cubic cells of edge `block_m` in G, one per occupied cell.

    Neighbouring pairs share their surface fit, so their residuals are correlated and a
    jackknife over stops cannot see a misfit every stop repeats; leaving out a block of space
    removes a correlated patch whole. The floor terms stay in every block's complement.
    `placed`: the clouds placed with these poses, where the caller has them.
    """
    layout = objective.layout
    if placed is None:
        placed = objective.place(stops, lidars)
    key = voxel_keys(placed.reference_G[pairs.target], block_m, "optimisation.uncertainty_block_m")
    blocks, block_of = np.unique(key, return_inverse=True)
    H = np.zeros((len(blocks), layout.size, layout.size))
    b = np.zeros((len(blocks), layout.size))
    order = np.argsort(block_of, kind="stable")
    bounds = np.searchsorted(block_of[order], np.arange(len(blocks) + 1))
    for c in range(len(blocks)):
        rows = order[bounds[c] : bounds[c + 1]]
        subset = pairs.take(rows)
        H[c], b[c], _, _ = normal_equations(
            objective, subset, stops, lidars, scale, with_floor=False, placed=placed
        )
    return H, b


def _rays_G(
    clouds_points: NDArray[np.float64],
    lidar_of: NDArray[np.int64],
    stop_of: NDArray[np.int64],
    stops: NDArray[np.float64],
    lidars: NDArray[np.float64],
) -> NDArray[np.float64]:
    """(N, 3) each point's unit ray direction (from its LiDAR, points (N, 3) in that LiDAR's
    frame), in G."""
    rays = clouds_points / np.maximum(np.linalg.norm(clouds_points, axis=1, keepdims=True), 1e-12)
    R_G_lidar = (stops[:, None, :3, :3] @ lidars[None, :, :3, :3])[stop_of, lidar_of]
    result: NDArray[np.float64] = np.einsum("nij,nj->ni", R_G_lidar, rays)
    return result


def range_bias_terms(
    objective: JointObjective,
    pairs: Pairs,
    stops: NDArray[np.float64],
    lidars: NDArray[np.float64],
    scale: float,
    placed: PlacedClouds | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The normal equations' terms of a range bias per LiDAR (beta_i: every point of LiDAR i
    moved along its ray by the same length), at fixed pairs: `J^T W dr/dbeta` (L, P) between
    the poses and each bias, `dr/dbeta^T W dr/dbeta` (L, L) among the biases, and
    `dr/dbeta^T W r` (L,), the cost's gradient by them. The floor terms are left out: they fix
    height, roll and pitch, and a floor plane a range bias moves stays a plane. `placed`: the
    clouds placed with these poses, where the caller has them."""
    layout = objective.layout
    if placed is None:
        placed = objective.place(stops, lidars)
    sorted_pairs, key = _grouped(objective, pairs)
    residual = point_residuals(objective.config.residual, sorted_pairs, placed)
    weight, _ = pair_weights_and_costs(objective, sorted_pairs, residual, scale)
    jac = point_jacobians(objective, sorted_pairs, placed, stops)
    src, tgt = objective.sources, objective.reference
    u_src = _rays_G(src.points, src.lidar, src.stop, stops, lidars)[sorted_pairs.source]
    u_tgt = _rays_G(tgt.points, tgt.lidar, tgt.stop, stops, lidars)[sorted_pairs.target]
    if objective.config.residual == "point_to_plane":
        normals = placed.normals_G[sorted_pairs.target]
        u_src = np.einsum("ni,ni->n", normals, u_src)[:, None]
        u_tgt = np.einsum("ni,ni->n", normals, u_tgt)[:, None]
    source_lidar = src.lidar[sorted_pairs.source]
    target_lidar = tgt.lidar[sorted_pairs.target]
    cross = np.zeros((layout.n_lidars, layout.size))
    scratch = np.zeros((layout.size, layout.size))
    derivatives = []
    for i in range(layout.n_lidars):
        # A pair of LiDAR i's own map moves at both ends; the two terms then cancel along the
        # normal only where the rays are parallel.
        d_residual = u_src * (source_lidar == i)[:, None] - u_tgt * (target_lidar == i)[:, None]
        derivatives.append(d_residual.reshape(-1))
        _add_point_groups(scratch, cross[i], objective, key, jac, weight, d_residual)
    d_rows = np.stack(derivatives)  # (L, residual rows)
    weighted = d_rows * np.repeat(weight, residual.shape[1])[None, :]
    return cross, weighted @ d_rows.T, weighted @ residual.reshape(-1)
