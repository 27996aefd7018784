"""What the joint optimisation returns."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.optimisation.layout import ParameterLayout


@dataclass(frozen=True)
class OptimisationResult:
    """Refined `T_G_ref` (J, 4, 4) and `T_ref_lidar` (L, 4, 4), with how it got there.

    `error_per_iteration[k]`: eq. 11 before step k (mean nearest-neighbour distance, metres, of
    the non-reference object points to the reference map), the last entry after the final step.
    `T_ref_lidar_per_iteration` (K + 1, L, 4, 4): the extrinsics before each step and at the end.
    `information` (P, P): J^T W J at the solution, weights in 1/sigma^2 (see `layout`), and
    `gradient` (P,) J^T W r there; `stop_information` (J, P, P) and `stop_gradient` (J, P): the
    parts of both that come from the residuals touching each stop (its points as source or as
    target, its floor planes), for a leave-one-stop-out jackknife (`pipeline.observability`);
    `block_information` (B, P, P) and `block_gradient` (B, P): the same for the point pairs
    whose target lies in each occupied block of space (`uncertainty_block_m`), for a
    leave-one-block-out jackknife; `range_bias_cross` (L, P), `range_bias_information` (L, L)
    and `range_bias_gradient` (L,): the normal equations' terms of a range bias per LiDAR (its
    points moved along their rays; `assembly.range_bias_terms`), from which the observability
    stage estimates each LiDAR's range bias and what it does to the poses (empty, 0 rows, unless
    `optimise(range_bias=True)`);
    `variance_factor`: a-posteriori sum of weighted squared residuals over the redundancy;
    `kernel_scale_m`: the robust kernel's scale these terms were assembled with (the last step's).
    """

    T_G_ref: NDArray[np.float64]
    T_ref_lidar: NDArray[np.float64]
    converged: bool
    iterations: int
    error_per_iteration: tuple[float, ...]
    T_ref_lidar_per_iteration: NDArray[np.float64]
    information: NDArray[np.float64]
    gradient: NDArray[np.float64]
    stop_information: NDArray[np.float64]
    stop_gradient: NDArray[np.float64]
    block_information: NDArray[np.float64]
    block_gradient: NDArray[np.float64]
    range_bias_cross: NDArray[np.float64]
    range_bias_information: NDArray[np.float64]
    range_bias_gradient: NDArray[np.float64]
    variance_factor: float
    layout: ParameterLayout
    correspondences: tuple[int, ...]
    residual_rms_m: float
    seconds: float
    kernel_scale_m: float
    accelerated_steps: int = 0
    """Steps whose poses Anderson acceleration extrapolated (`OptimisationConfig.acceleration`)."""
