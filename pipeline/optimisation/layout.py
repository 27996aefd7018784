"""Where each pose's twist sits in the joint optimisation's state vector, and the poses a
step of it moves to."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.geometry import exp_se3


@dataclass(frozen=True)
class ParameterLayout:
    """Where each pose's 6 parameters sit in the state vector; stop 0 and LiDAR 0 are fixed."""

    n_stops: int
    n_lidars: int

    @property
    def size(self) -> int:
        return 6 * (self.n_stops - 1 + self.n_lidars - 1)

    def stop(self, index: int) -> int:
        """First column of stop `index`, -1 when fixed."""
        return -1 if index == 0 else 6 * (index - 1)

    def lidar(self, index: int) -> int:
        """First column of LiDAR `index`, -1 when fixed."""
        return -1 if index == 0 else 6 * (self.n_stops - 1) + 6 * (index - 1)


def apply_step(
    step: NDArray[np.float64],
    layout: ParameterLayout,
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The poses moved by the state-vector `step` (P,): each pose's twist on its left."""
    new_stops, new_lidars = T_G_ref.copy(), T_ref_lidar.copy()
    for j in range(1, layout.n_stops):
        c = layout.stop(j)
        new_stops[j] = exp_se3(step[c : c + 6]) @ T_G_ref[j]
    for i in range(1, layout.n_lidars):
        c = layout.lidar(i)
        new_lidars[i] = exp_se3(step[c : c + 6]) @ T_ref_lidar[i]
    return new_stops, new_lidars
