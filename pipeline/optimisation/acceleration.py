"""Anderson acceleration of stage 4's iteration: pair, then one Levenberg-Marquardt step.

Re-pairing after every step makes the iteration a fixed-point map x -> G(x) whose convergence is
linear, and slow along the directions the pairs hold weakly: the poses creep a tenth of a
millimetre a step for hundreds of steps and the run ends on its iteration limit short of the
solution. Anderson acceleration (type II, as in Walker and Ni 2011; for ICP, Pavlov et al. 2018)
extrapolates from the last few steps: with the residuals f_k = G(x_k) - x_k, it takes the
combination of the last steps' G(x) whose residual is least in the least-squares sense,
`x_next = G(x_k) - dG gamma`, `gamma = argmin |f_k - dF gamma|`. The poses are handled as twists
on the left of where the phase started (`ParameterLayout`'s order), so the extrapolation is a
linear one in a vector space; the caller keeps an extrapolated step only where its cost with
fresh pairs is below the plain step's, which makes it safe however far the map is from linear.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.geometry import log_se3
from pipeline.optimisation.layout import ParameterLayout, apply_step

Poses = tuple[NDArray[np.float64], NDArray[np.float64]]
"""`T_G_ref` (J, 4, 4) of the stops and `T_ref_lidar` (L, 4, 4) of the LiDARs."""


class AndersonAcceleration:
    """The last `depth` + 1 steps of one phase, and the extrapolated poses they give."""

    def __init__(self, layout: ParameterLayout, start: Poses, depth: int) -> None:
        self.layout, self.depth = layout, depth
        self.start_stops, self.start_lidars = (np.array(poses) for poses in start)
        self.inputs: list[NDArray[np.float64]] = []
        self.outputs: list[NDArray[np.float64]] = []

    def propose(self, before: Poses, after: Poses) -> Poses | None:
        """Record the step `before` -> `after` (one pairing and LM step) and return the poses
        extrapolated from the steps recorded, or None while there is only one."""
        self.inputs = [*self.inputs, self.twists(before)][-(self.depth + 1) :]
        self.outputs = [*self.outputs, self.twists(after)][-(self.depth + 1) :]
        if len(self.inputs) < 2:
            return None
        outputs = np.stack(self.outputs, axis=1)
        residuals = outputs - np.stack(self.inputs, axis=1)
        gamma, *_ = np.linalg.lstsq(np.diff(residuals, axis=1), residuals[:, -1], rcond=None)
        return self.poses(outputs[:, -1] - np.diff(outputs, axis=1) @ gamma)

    def keep_last(self) -> None:
        """Forget every step but the last (after an extrapolation that did not lower the cost)."""
        self.inputs, self.outputs = self.inputs[-1:], self.outputs[-1:]

    def twists(self, poses: Poses) -> NDArray[np.float64]:
        """(P,) each free pose's twist on the left of its start, in the layout's order."""
        stops, lidars = poses
        x = np.zeros(self.layout.size)
        for column, pose, start in self._free(stops, lidars):
            x[column : column + 6] = log_se3(pose @ np.linalg.inv(start))
        return x

    def poses(self, x: NDArray[np.float64]) -> Poses:
        """The poses at the twists `x` (P,): the inverse of `twists`."""
        return apply_step(x, self.layout, self.start_stops, self.start_lidars)

    def _free(
        self, stops: NDArray[np.float64], lidars: NDArray[np.float64]
    ) -> list[tuple[int, NDArray[np.float64], NDArray[np.float64]]]:
        """(column, pose, its start) of every free pose: stops and LiDARs but the first of each."""
        layout = self.layout
        return [
            (layout.stop(j), stops[j], self.start_stops[j]) for j in range(1, layout.n_stops)
        ] + [(layout.lidar(i), lidars[i], self.start_lidars[i]) for i in range(1, layout.n_lidars)]
