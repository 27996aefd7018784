"""Each point pair's residual standard deviation, measured per pair of LiDARs.

Why: LiDARs on one robot scatter their smoothed surfaces very differently (a 16-beam spinning
head under 30 mm of range noise, whose patches span one or two scan lines, against a rosette
under 20 mm whose patches are dense), and a cost that weighs every pair alike lets the noisiest
map pull the others. On `bench_random` seed 1013 (four LiDARs, one of them a spinning head whose
object points lie more than 1 cm from the true surfaces for most of them after smoothing),
stage 4 started at the true poses walked to 4.1 / 7.2 / 3.3 mm; weighing that head's pairs
a tenth, to 2.0 / 2.7 / 1.0 mm.

How: at every association the point-to-plane residuals of each group of pairs with the same
source and target LiDAR give that group's robust sigma (`residuals.robust_sigma`) over its
inliers; every pair takes its group's. Inliers, because a group can hold more far pairs than
near ones: on a rig of four (`bench_random` seed 1032) a 16-beam head saw few of the objects
the others saw, so most points of the others found their nearest neighbour in its map on
another object, 0.3-0.5 m away; the median over all of them read 285-500 mm, whitening put
those pairs inside the robust kernel, and thousands of them, each weighed little, pulled: the
head ended 7.7 mm off, 6.6 mm with the sigmas measured on inliers (5.7 mm with uniform
weights; its 1-sigma is 15-17 mm). The sigma is re-measured on the residuals within
`INLIER_SIGMAS` of the last estimate, from the pooled one, until it settles. The sigmas are
then rescaled together so that the pairs' mean weight stays `1 / point_sigma_m^2`: the points
weigh against the floor terms and the stops' prior as before, only among themselves do they
weigh by their noise.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from pipeline.optimisation.association import Pairs
from pipeline.optimisation.objective import JointObjective, PlacedClouds
from pipeline.optimisation.residuals import point_residuals, robust_sigma

MIN_GROUP_PAIRS = 50
"""A group of fewer inlier pairs than this takes the sigma of all pairs together."""

INLIER_SIGMAS = 4.0
"""A pair is an inlier of its group while its residual is within this many of the group's
sigma (a normal residual falls outside 4 sigmas once in 16,000 in 1-D, once in 1,000 as a
3-D norm)."""

INLIER_ROUNDS = 4
"""Re-measurements of a group's sigma on its inliers: from a start a third of the truth, the
estimate reaches 0.8, 0.99 and 1.0 of it."""


def with_lidar_pair_sigmas(objective: JointObjective, pairs: Pairs, placed: PlacedClouds) -> Pairs:
    """`pairs` with each one's `sigma`: the robust sigma of its group's residuals (same source
    and target LiDAR) at the poses `placed`, rescaled as the module says."""
    if len(pairs.source) == 0:
        return pairs
    residual = point_residuals(objective.config.residual, pairs, placed)
    n_lidars = objective.layout.n_lidars
    group = (
        objective.sources.lidar[pairs.source] * n_lidars + objective.reference.lidar[pairs.target]
    )
    pooled = max(robust_sigma(residual), 1e-6)
    sigma = np.full(len(pairs.source), pooled)
    for key in np.unique(group):
        rows = group == key
        sigma[rows] = _inlier_sigma(residual[rows], pooled)
    unit = objective.config.point_sigma_m
    sigma *= unit * np.sqrt(np.mean(1.0 / sigma**2))
    return dataclasses.replace(pairs, sigma=sigma)


def _inlier_sigma(residual: NDArray[np.float64], start: float) -> float:
    """The robust sigma of `residual` (n, rows) over its inliers (within `INLIER_SIGMAS` of the
    estimate), re-measured `INLIER_ROUNDS` times from `start`; `start` where fewer than
    `MIN_GROUP_PAIRS` are inliers."""
    norms = np.linalg.norm(residual, axis=1)
    sigma = start
    for _ in range(INLIER_ROUNDS):
        inliers = norms <= INLIER_SIGMAS * sigma
        if np.count_nonzero(inliers) < MIN_GROUP_PAIRS:
            return start
        sigma = max(robust_sigma(residual[inliers]), 1e-6)
    return sigma
