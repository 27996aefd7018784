"""Association: each source point's nearest neighbour in a target map (kd-tree), gated by
distance and by the way the two surfaces face.

Cross pairs: points of the other LiDARs against the reference LiDAR's map (eq. 11 of the paper),
and with `cross_pairs: every_lidar` every LiDAR's points against every other LiDAR's map too.
Self pairs: a LiDAR's points against its own map as seen from another stop (self-consistency).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from pykdtree.kdtree import KDTree

from pipeline.optimisation.objective import JointObjective, PlacedClouds


@dataclass(frozen=True)
class Pairs:
    """Associations of one iteration: source rows, target rows in the reference map, and where
    measured (`pair_noise`), each pair's residual standard deviation `sigma` (m; None: every
    pair's is `point_sigma_m`)."""

    source: NDArray[np.int64]
    target: NDArray[np.int64]
    cross_error: float  # eq. 11 over every non-reference point (no gate)
    sigma: NDArray[np.float64] | None = None

    def take(self, rows: NDArray[np.int64] | NDArray[np.bool_]) -> Pairs:
        """The pairs at `rows` (indices or a mask), with their sigmas."""
        sigma = None if self.sigma is None else self.sigma[rows]
        return Pairs(self.source[rows], self.target[rows], self.cross_error, sigma)


def associate(objective: JointObjective, placed: PlacedClouds) -> Pairs:
    """The pairs of every source point with a target point within `max_correspondence_m`;
    eq. 11 (`cross_error`) over the pairs with the reference's map alone."""
    empty = np.zeros(0, dtype=np.int64)
    if len(objective.reference.points) == 0 or len(objective.sources.points) == 0:
        return Pairs(empty, empty, float("nan"))
    sources, targets = [], []
    cross_error = float("nan")
    every_lidar = objective.config.pairs_every_lidar(objective.layout.n_lidars)
    for lidar in range(objective.layout.n_lidars):
        rows = np.flatnonzero(objective.reference.lidar == lidar)
        if len(rows) == 0:
            continue
        tree = KDTree(placed.reference_G[rows])
        if lidar == 0 or every_lidar:
            cross = np.flatnonzero(objective.sources.lidar != lidar)
            if len(cross):
                source, target, error = _cross_pairs(objective, placed, tree, rows, cross)
                sources.append(source)
                targets.append(target)
                if lidar == 0:
                    cross_error = error
        own = np.flatnonzero(objective.sources.lidar == lidar)
        if len(own) == 0:
            continue
        source, target = _self_pairs(objective, placed, tree, rows, own)
        sources.append(source)
        targets.append(target)
    return Pairs(
        np.concatenate(sources) if sources else empty,
        np.concatenate(targets) if targets else empty,
        cross_error,
    )


def _cross_pairs(
    objective: JointObjective,
    placed: PlacedClouds,
    tree: KDTree,
    rows: NDArray[np.int64],
    cross: NDArray[np.int64],
) -> tuple[NDArray[np.int64], NDArray[np.int64], float]:
    """Source rows `cross` paired with their nearest point of one LiDAR's map (`tree` over its
    target `rows`), and the mean distance over all of them before any gate (eq. 11 when that
    map is the reference's)."""
    distance, index = tree.query(placed.source_G[cross], k=1)
    cross_error = float(np.mean(distance))
    nearest = rows[index.astype(np.int64)]
    keep = (distance < objective.config.max_correspondence_m) & _compatible(
        objective, placed, cross, nearest
    )
    return cross[keep], nearest[keep], cross_error


def _self_pairs(
    objective: JointObjective,
    placed: PlacedClouds,
    tree: KDTree,
    rows: NDArray[np.int64],
    own: NDArray[np.int64],
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Source rows `own` of one LiDAR paired with the nearest point of the same LiDAR's map
    (`tree` over its target `rows`) seen from *another* stop: a stop's own points would tie
    every point to itself. Among the `self_neighbours` nearest, the first from another stop."""
    k = min(objective.config.self_neighbours, len(rows))
    _, index = tree.query(
        placed.source_G[own], k=k, distance_upper_bound=objective.config.max_correspondence_m
    )
    index = index.reshape(len(own), k)
    found = index < len(rows)
    candidates = rows[np.where(found, index, 0)]
    other = found & (objective.reference.stop[candidates] != objective.sources.stop[own][:, None])
    first = np.argmax(other, axis=1)
    nearest = candidates[np.arange(len(own)), first]
    keep = other[np.arange(len(own)), first]
    keep[keep] &= _compatible(objective, placed, own[keep], nearest[keep])
    return own[keep], nearest[keep]


def _compatible(
    objective: JointObjective,
    placed: PlacedClouds,
    source: NDArray[np.int64],
    target: NDArray[np.int64],
) -> NDArray[np.bool_]:
    """Pairs whose surfaces face the same way (within `max_normal_angle_deg`)."""
    max_angle = objective.config.max_normal_angle_deg
    if max_angle is None:
        return np.ones(len(source), dtype=bool)
    cos = np.einsum("ni,ni->n", placed.source_normals_G[source], placed.normals_G[target])
    result: NDArray[np.bool_] = cos >= np.cos(np.radians(max_angle))
    return result
