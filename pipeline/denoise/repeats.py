"""Range-gap test for a repetitive scan: support only from directions that see one surface.

A spinning LiDAR fires the same directions every scan, so a stop cloud holds each direction many
times over (a 16-beam head standing 1.5 s: 15 returns per direction). At a depth edge the beam
straddles the near and far surfaces, and its repeats are a mix of near returns, far returns and
mixed ones; an energy-weighted receiver mixes at similar fractions scan after scan, so a mixed
return finds support among its own repeats and among the kNN of raw points (those are mostly the
same direction's repeats), which is why the generic range-gap test missed most of them.

Here every distinct direction is summarised by its returns (all in the LiDAR frame, ranges in
metres from the sensor): their median range, and whether it is *pure*, i.e. its repeats agree
within the range noise (interquartile range <= `purity_iqr_sigmas` sigmas; a Gaussian gives
1.35). A point is bleeding when no pure direction among its own and its `k` nearest distinct
directions has its median within `tau` of the point's range: no surface a whole beam sees lies
where it does. A point whose neighbourhood holds no pure direction at all is kept (nothing to
judge it by). Mixed beams lie within the beam's divergence of an edge, so the pure directions on
both sides of the band of mixed beams give the surfaces, whatever the divergence, as long as `k`
distinct directions reach across the band (16 azimuth steps of 0.2 deg: 1.6 deg either side).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.denoise.filters import KeepMask, Points

# Directions are compared after rounding unit vectors to this many parts per unit: exact repeats
# (the same firing direction scaled by another range) coincide, a rosette's neighbours (1e-3
# apart) do not.
_UNIT_STEPS = 1_000_000
_AXIS_BITS = 21
# A direction needs this many returns for its interquartile range to say whether it is pure.
_MIN_REPEATS = 4


@dataclass(frozen=True)
class DirectionGroups:
    """The cloud's distinct directions: `of_point` (N,) the direction of each point, `units`
    (D, 3) unit vectors, `median_m` (D,) median range, `iqr_m` (D,) interquartile range,
    `count` (D,) returns per direction."""

    of_point: NDArray[np.intp]
    units: Points
    median_m: NDArray[np.float64]
    iqr_m: NDArray[np.float64]
    count: NDArray[np.intp]


def group_directions(cloud: Points) -> DirectionGroups:
    """Group the points of `cloud` (N, 3, sensor at the origin) by exact repeats of direction."""
    ranges = np.linalg.norm(cloud, axis=1)
    units = cloud / np.where(ranges > 0.0, ranges, 1.0)[:, None]
    steps = np.rint(units * _UNIT_STEPS).astype(np.int64) + (1 << (_AXIS_BITS - 1))
    key = (steps[:, 0] << (2 * _AXIS_BITS)) | (steps[:, 1] << _AXIS_BITS) | steps[:, 2]
    _, of_point = np.unique(key, return_inverse=True)
    of_point = of_point.reshape(-1).astype(np.intp)
    count = np.bincount(of_point).astype(np.intp)
    order = np.lexsort((ranges, of_point))
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    sorted_ranges = ranges[order]

    def quantile(q: float) -> NDArray[np.float64]:
        return np.asarray(sorted_ranges[start + np.floor(q * (count - 1)).astype(np.intp)])

    group_units = np.zeros((len(count), 3))
    group_units[of_point] = units
    return DirectionGroups(
        of_point=of_point,
        units=group_units,
        median_m=quantile(0.5),
        iqr_m=quantile(0.75) - quantile(0.25),
        count=count,
    )


def has_repeats(groups: DirectionGroups) -> bool:
    """Whether most points' directions repeat often enough to judge purity by."""
    return bool(np.median(groups.count[groups.of_point]) >= _MIN_REPEATS)


def pure_support_keep(
    cloud: Points,
    groups: DirectionGroups,
    *,
    k: int,
    tau_m: float,
    pure_iqr_m: float,
    rows: NDArray[np.intp] | None = None,
) -> KeepMask:
    """Keep mask of the points `rows` of `cloud` (all when None): False where no pure direction
    among the point's own and its `k` nearest distinct directions has a median range within
    `tau_m` of the point's range, and at least one of them is pure (see the module docstring)."""
    from pykdtree.kdtree import KDTree

    own = np.arange(len(cloud)) if rows is None else rows
    directions = np.ascontiguousarray(groups.units, dtype=np.float32)
    neighbours = min(k + 1, len(directions))
    _, index = KDTree(directions, leafsize=32).query(directions, k=neighbours)
    index = index.reshape(len(directions), neighbours)
    pure = (groups.iqr_m <= pure_iqr_m) & (groups.count >= _MIN_REPEATS)
    near = index[groups.of_point[own]]
    ranges = np.linalg.norm(cloud[own], axis=1)
    near_pure = pure[near]
    supported = near_pure & (np.abs(groups.median_m[near] - ranges[:, None]) <= tau_m)
    return np.asarray(supported.any(axis=1) | ~near_pure.any(axis=1), dtype=np.bool_)
