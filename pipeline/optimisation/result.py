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
    `variance_factor`: a-posteriori sum of weighted squared residuals over the redundancy.
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
    variance_factor: float
    layout: ParameterLayout
    correspondences: tuple[int, ...]
    residual_rms_m: float
    seconds: float
