"""Each point pair's residual standard deviation, measured per pair of LiDARs.

Why: LiDARs on one robot scatter their smoothed surfaces very differently (a 16-beam spinning
head under 30 mm of range noise, whose patches span one or two scan lines, against a rosette
under 20 mm whose patches are dense), and a cost that weighs every pair alike lets the noisiest
map pull the others. On `bench_random` seed 1013 (four LiDARs, one of them a spinning head whose
object points lie more than 1 cm from the true surfaces for most of them after smoothing),
stage 4 started at the true poses walked to 4.1 / 7.2 / 3.3 mm; weighing that head's pairs
a tenth, to 2.0 / 2.7 / 1.0 mm.

How: at every association the point-to-plane residuals of each group of pairs with the same
source and target LiDAR give that group's robust sigma (`residuals.robust_sigma`); every pair
takes its group's. The sigmas are then rescaled together so that the pairs' mean weight stays
`1 / point_sigma_m^2`: the points weigh against the floor terms and the stops' prior as before,
only among themselves do they weigh by their noise.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.optimisation.association import Pairs
from pipeline.optimisation.objective import JointObjective, PlacedClouds
from pipeline.optimisation.residuals import point_residuals, robust_sigma

MIN_GROUP_PAIRS = 50
"""A group of fewer pairs than this takes the sigma of all pairs together."""


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
        if np.count_nonzero(rows) >= MIN_GROUP_PAIRS:
            sigma[rows] = max(robust_sigma(residual[rows]), 1e-6)
    unit = objective.config.point_sigma_m
    sigma *= unit * np.sqrt(np.mean(1.0 / sigma**2))
    return dataclasses.replace(pairs, sigma=sigma)
