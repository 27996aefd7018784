"""Where each pose's twist sits in the joint optimisation's state vector."""

from __future__ import annotations

from dataclasses import dataclass


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
