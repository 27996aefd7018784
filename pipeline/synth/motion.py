"""Stop-and-go motion of the robot: true base poses and twists over time, and odometry drift.

The robot stands still at each stop, then moves to the next along a circular arc with a
minimum-jerk profile (zero speed and acceleration at both ends). Radius 0 is rotation in place;
a positive radius is a differential-drive robot driving a loop, always heading along the arc.
Times are seconds since the recording started.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field
from scipy.spatial.transform import Rotation

from pipeline.transforms import Matrix4

FloatArray = NDArray[np.float64]


class ArcMotion(BaseModel):
    """`stops` stops `dwell_s` long, each `step_deg` further round a circle of `radius_m`.

    The circle's centre is the world origin; at heading `theta` the base sits at
    `radius * (sin theta, -cos theta)` facing `theta` (so radius 0 turns on the spot at the origin).
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    stops: int = Field(default=16, ge=1)
    radius_m: float = Field(default=0.0, ge=0)
    step_deg: float = 22.5
    start_deg: float = 0.0
    dwell_s: float = Field(default=1.5, gt=0)
    move_s: float = Field(default=0.5, gt=0)

    @property
    def duration_s(self) -> float:
        return self.stops * self.dwell_s + (self.stops - 1) * self.move_s

    def stop_intervals(self) -> FloatArray:
        """(stops, 2) start and end of each stop."""
        starts = np.arange(self.stops) * (self.dwell_s + self.move_s)
        return np.column_stack([starts, starts + self.dwell_s])

    def progress(self, t: FloatArray) -> tuple[NDArray[np.int64], FloatArray, FloatArray]:
        """For times `t` (K,): the last stop reached `j`, the progress `s` in [0, 1] towards
        stop `j + 1` (0 while standing) and `ds/dt`."""
        t = np.asarray(t, dtype=np.float64)
        period = self.dwell_s + self.move_s
        j = np.clip(np.floor(t / period).astype(np.int64), 0, self.stops - 1)
        tau = np.clip((t - j * period - self.dwell_s) / self.move_s, 0.0, 1.0)
        tau = np.where(j == self.stops - 1, 0.0, tau)
        s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
        ds_dt = 30.0 * tau**2 * (1.0 - tau) ** 2 / self.move_s
        return j, s, ds_dt

    def heading(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Heading `theta` (rad) and turn rate (rad/s) at times `t` (K,)."""
        j, s, ds_dt = self.progress(t)
        step = math.radians(self.step_deg)
        return math.radians(self.start_deg) + step * (j + s), step * ds_dt

    def poses(self, t: FloatArray) -> NDArray[np.float64]:
        """True `T_world_base` (K, 4, 4) at times `t` (K,)."""
        theta, _ = self.heading(t)
        T = np.zeros((len(theta), 4, 4))
        T[:, :3, :3] = Rotation.from_euler("z", theta[:, None]).as_matrix()
        T[:, 0, 3] = self.radius_m * np.sin(theta)
        T[:, 1, 3] = -self.radius_m * np.cos(theta)
        T[:, 3, 3] = 1.0
        return T

    def twist(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Linear and angular velocity (K, 3) each, in the base frame (forward = +x)."""
        _, rate = self.heading(t)
        zeros = np.zeros_like(rate)
        return (
            np.column_stack([self.radius_m * rate, zeros, zeros]),
            np.column_stack([zeros, zeros, rate]),
        )


def interpolate_drift(
    motion: ArcMotion, deltas: NDArray[np.float64], t: FloatArray
) -> NDArray[np.float64]:
    """Odometry error `delta(t)` (K, 4, 4) from one error per stop, `deltas` (stops, 4, 4).

    Constant during a stop, and moving smoothly from one stop's error to the next while the
    robot moves (translation along the chord, rotation along the geodesic), as odometry drifts.
    Both paths stay inside the bounds the per-stop errors were drawn in (balls are convex).
    """
    j, s, _ = motion.progress(t)
    nxt = np.minimum(j + 1, motion.stops - 1)
    rot = Rotation.from_matrix(deltas[:, :3, :3])
    relative = (rot[j].inv() * rot[nxt]).as_rotvec()
    out = np.zeros((len(j), 4, 4))
    out[:, :3, :3] = (rot[j] * Rotation.from_rotvec(relative * s[:, None])).as_matrix()
    out[:, :3, 3] = (1.0 - s)[:, None] * deltas[j, :3, 3] + s[:, None] * deltas[nxt, :3, 3]
    out[:, 3, 3] = 1.0
    return out


def true_stop_poses(motion: ArcMotion) -> list[Matrix4]:
    """True `T_world_base` of every stop."""
    return list(motion.poses(motion.stop_intervals()[:, 0]))
