"""Stop-and-go motion of the robot: true base poses and twists over time, and odometry drift.

A route is a start pose, a dwell per stop and, between consecutive stops, a leg of planar
segments driven one after the other: straight drives and circular arcs (radius 0 turns on the
spot). Each segment follows a minimum-jerk profile (zero speed and acceleration at both ends:
the acceleration ramps of a real base), so the robot is still between segments and during the
dwells. A differential-drive base always heads along its path. Times are seconds since the
recording started. `ArcMotion` is the paper's routine (equal stops round one circle) written
as such a route.
"""

from __future__ import annotations

import functools
import math
from functools import cached_property
from typing import Annotated, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, model_validator
from scipy.spatial.transform import Rotation

from pipeline.transforms import Matrix4

FloatArray = NDArray[np.float64]
_FROZEN = ConfigDict(frozen=True, extra="forbid")
MIN_JERK_PEAK = 1.875
"""Peak over mean speed of a minimum-jerk move: a move of length d at peak speed v lasts
`1.875 d / v`."""


class Straight(BaseModel):
    """Drive `distance_m` along the current heading (negative: in reverse)."""

    model_config = _FROZEN

    kind: Literal["straight"] = "straight"
    distance_m: float
    duration_s: float = Field(gt=0)


class Arc(BaseModel):
    """Turn by `angle_deg` (counter-clockwise positive) round a centre `radius_m` to the left
    (negative: to the right). Radius 0 turns on the spot; the base drives forward when radius
    and angle have the same sign, in reverse otherwise."""

    model_config = _FROZEN

    kind: Literal["arc"] = "arc"
    radius_m: float = 0.0
    angle_deg: float
    duration_s: float = Field(gt=0)


Segment = Annotated[Straight | Arc, Field(discriminator="kind")]


def _min_jerk(tau: FloatArray, duration: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Progress `s` in [0, 1] and `ds/dt` at normalised times `tau` (clipped to [0, 1])."""
    tau = np.clip(tau, 0.0, 1.0)
    s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    return s, 30.0 * tau**2 * (1.0 - tau) ** 2 / duration


class RouteMotion(BaseModel):
    """Stops `dwell_s` long joined by `legs`: leg `j` takes the base from stop `j` to `j + 1`.

    `start` is the first stop's pose in the world: x (m), y (m), heading (deg).
    """

    model_config = _FROZEN

    kind: Literal["route"] = "route"
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)
    dwell_s: tuple[Annotated[float, Field(gt=0)], ...] = Field(min_length=1)
    legs: tuple[tuple[Segment, ...], ...]

    @model_validator(mode="after")
    def _check(self) -> RouteMotion:
        if len(self.legs) != len(self.dwell_s) - 1 or any(len(leg) == 0 for leg in self.legs):
            raise ValueError(
                f"a route with {len(self.dwell_s)} stops needs {len(self.dwell_s) - 1} legs of "
                f"one or more segments each; got {[len(leg) for leg in self.legs]}"
            )
        return self

    @property
    def stops(self) -> int:
        return len(self.dwell_s)

    @property
    def duration_s(self) -> float:
        return float(self._stop_times[-1, 1])

    def stop_intervals(self) -> FloatArray:
        """(stops, 2) start and end of each stop."""
        return self._stop_times.copy()

    @property
    def _stop_times(self) -> FloatArray:
        return _timeline(self)[0]

    @property
    def _table(self) -> dict[str, FloatArray]:
        return _timeline(self)[1]

    def _at(self, t: FloatArray) -> tuple[dict[str, FloatArray], FloatArray, FloatArray]:
        """The segment each time falls in (or last finished), its progress `s` and `ds/dt`."""
        t = np.asarray(t, dtype=np.float64)
        table = self._table
        if not len(table["start"]):
            rest = {name: np.zeros(len(t)) for name in table}
            rest["x"][:], rest["y"][:] = self.start[0], self.start[1]
            rest["yaw"][:] = math.radians(self.start[2])
            return rest, np.zeros(len(t)), np.zeros(len(t))
        k = np.searchsorted(table["start"], t, side="right") - 1
        before = k < 0
        k = np.maximum(k, 0)
        row = {name: values[k] for name, values in table.items()}
        s, ds_dt = _min_jerk((t - row["start"]) / row["duration"], row["duration"])
        # Before the first segment starts the base rests at the route's start.
        return row, np.where(before, 0.0, s), np.where(before, 0.0, ds_dt)

    def heading(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Heading `theta` (rad) and turn rate (rad/s) at times `t` (K,)."""
        row, s, ds_dt = self._at(t)
        return row["yaw"] + row["angle"] * s, row["angle"] * ds_dt

    def poses(self, t: FloatArray) -> NDArray[np.float64]:
        """True `T_world_base` (K, 4, 4) at times `t` (K,)."""
        row, s, _ = self._at(t)
        x, y, yaw = _advance(
            row["x"], row["y"], row["yaw"], row["distance"], row["radius"], row["angle"], s
        )
        T = np.zeros((len(s), 4, 4))
        T[:, :3, :3] = Rotation.from_euler("z", np.asarray(yaw)[:, None]).as_matrix()
        T[:, 0, 3], T[:, 1, 3], T[:, 3, 3] = x, y, 1.0
        return T

    def twist(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Linear and angular velocity (K, 3) each, in the base frame (forward = +x)."""
        row, _, ds_dt = self._at(t)
        zeros = np.zeros_like(ds_dt)
        forward = (row["distance"] + row["radius"] * row["angle"]) * ds_dt
        return (
            np.column_stack([forward, zeros, zeros]),
            np.column_stack([zeros, zeros, row["angle"] * ds_dt]),
        )

    def progress(self, t: FloatArray) -> tuple[NDArray[np.int64], FloatArray, FloatArray]:
        """For times `t` (K,): the last stop reached `j`, the progress `s` in [0, 1] towards
        stop `j + 1` over the whole leg (0 while standing) and `ds/dt`."""
        t = np.asarray(t, dtype=np.float64)
        stops = self._stop_times
        j = np.clip(np.searchsorted(stops[:, 0], t, side="right") - 1, 0, self.stops - 1)
        nxt = np.minimum(j + 1, self.stops - 1)
        leg = np.maximum(stops[nxt, 0] - stops[j, 1], 1e-12)
        s, ds_dt = _min_jerk((t - stops[j, 1]) / leg, leg)
        last = j == self.stops - 1
        return j.astype(np.int64), np.where(last, 0.0, s), np.where(last, 0.0, ds_dt)

    def path_xy(self, step_m: float = 0.05) -> FloatArray:
        """(K, 2) points along the driven path, at most `step_m` apart, the stops included."""
        table = self._table
        samples = [self.stop_intervals()[:, 0]]
        lengths = np.abs(table["distance"]) + np.abs(table["radius"] * table["angle"])
        for start, duration, length in zip(table["start"], table["duration"], lengths, strict=True):
            # A minimum-jerk move peaks at 1.875 times its mean speed: sample that much denser.
            count = max(2, math.ceil(MIN_JERK_PEAK * length / step_m) + 1)
            samples.append(np.linspace(start, start + duration, count))
        return self.poses(np.sort(np.concatenate(samples)))[:, :2, 3]

    def radius_band_m(self) -> tuple[float, float]:
        """Nearest and farthest the base's centre comes to the world origin."""
        radius = np.linalg.norm(self.path_xy(), axis=1)
        return float(radius.min()), float(radius.max())

    def travel_m(self, half_track_m: float) -> FloatArray:
        """(stops,) wheel travel from the start to each stop: distance driven plus
        `half_track_m` per radian turned (what wheel odometry integrates, and drifts with)."""
        table = self._table
        per_segment = np.abs(table["distance"]) + (np.abs(table["radius"]) + half_track_m) * np.abs(
            table["angle"]
        )
        per_leg = [0.0]
        k = 0
        for leg in self.legs:
            per_leg.append(float(per_segment[k : k + len(leg)].sum()))
            k += len(leg)
        return np.cumsum(per_leg)


@functools.lru_cache(maxsize=32)
def _timeline(route: RouteMotion) -> tuple[FloatArray, dict[str, FloatArray]]:
    """(stops, 2) start and end of each stop; per segment: start time, duration, signed radius,
    angle (rad), distance and start pose. Cached per route (a frozen, hashable model) rather
    than on it, so that two equal routes still compare equal (pydantic compares `__dict__`)."""
    stop_times = np.zeros((route.stops, 2))
    t = 0.0
    for j, dwell in enumerate(route.dwell_s):
        stop_times[j] = (t, t + dwell)
        t += dwell + (sum(s.duration_s for s in route.legs[j]) if j < len(route.legs) else 0.0)
    n = sum(len(leg) for leg in route.legs)
    table = {
        name: np.zeros(n)
        for name in ("start", "duration", "radius", "angle", "distance", "x", "y", "yaw")
    }
    x, y, yaw = route.start[0], route.start[1], math.radians(route.start[2])
    k = 0
    for j, leg in enumerate(route.legs):
        t = float(stop_times[j, 1])
        for segment in leg:
            radius = segment.radius_m if isinstance(segment, Arc) else 0.0
            angle = math.radians(segment.angle_deg) if isinstance(segment, Arc) else 0.0
            distance = segment.distance_m if isinstance(segment, Straight) else 0.0
            for name, value in (
                ("start", t),
                ("duration", segment.duration_s),
                ("radius", radius),
                ("angle", angle),
                ("distance", distance),
                ("x", x),
                ("y", y),
                ("yaw", yaw),
            ):
                table[name][k] = value
            end = _advance(x, y, yaw, distance, radius, angle, 1.0)
            x, y, yaw = float(end[0]), float(end[1]), float(end[2])
            t += segment.duration_s
            k += 1
    return stop_times, table


def _advance(
    x: FloatArray | float,
    y: FloatArray | float,
    yaw: FloatArray | float,
    distance: FloatArray | float,
    radius: FloatArray | float,
    angle: FloatArray | float,
    s: FloatArray | float,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Pose after fraction `s` of a segment (a straight has angle and radius 0, an arc
    distance 0): the arc's centre lies `radius` to the left of the start."""
    end_yaw = np.asarray(yaw + np.multiply(angle, s), dtype=np.float64)
    cos0, sin0 = np.cos(yaw), np.sin(yaw)
    end_x = x + np.multiply(distance, s) * cos0 + np.multiply(radius, np.sin(end_yaw) - sin0)
    end_y = y + np.multiply(distance, s) * sin0 + np.multiply(radius, cos0 - np.cos(end_yaw))
    return np.asarray(end_x, dtype=np.float64), np.asarray(end_y, dtype=np.float64), end_yaw


class ArcMotion(BaseModel):
    """`stops` stops `dwell_s` long, each `step_deg` further round a circle of `radius_m`.

    The circle's centre is the world origin; at heading `theta` the base sits at
    `radius * (sin theta, -cos theta)` facing `theta` (so radius 0 turns on the spot at the origin).
    """

    model_config = _FROZEN

    kind: Literal["arc"] = "arc"
    stops: int = Field(default=16, ge=1)
    radius_m: float = Field(default=0.0, ge=0)
    step_deg: float = 22.5
    start_deg: float = 0.0
    dwell_s: float = Field(default=1.5, gt=0)
    move_s: float = Field(default=0.5, gt=0)

    @cached_property
    def route(self) -> RouteMotion:
        theta = math.radians(self.start_deg)
        step = Arc(radius_m=self.radius_m, angle_deg=self.step_deg, duration_s=self.move_s)
        return RouteMotion(
            start=(
                self.radius_m * math.sin(theta),
                -self.radius_m * math.cos(theta),
                self.start_deg,
            ),
            dwell_s=(self.dwell_s,) * self.stops,
            legs=((step,),) * (self.stops - 1),
        )

    @property
    def duration_s(self) -> float:
        return self.stops * self.dwell_s + (self.stops - 1) * self.move_s

    def stop_intervals(self) -> FloatArray:
        return self.route.stop_intervals()

    def progress(self, t: FloatArray) -> tuple[NDArray[np.int64], FloatArray, FloatArray]:
        return self.route.progress(t)

    def heading(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        return self.route.heading(t)

    def poses(self, t: FloatArray) -> NDArray[np.float64]:
        return self.route.poses(t)

    def twist(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        return self.route.twist(t)

    def travel_m(self, half_track_m: float) -> FloatArray:
        return self.route.travel_m(half_track_m)

    def path_xy(self, step_m: float = 0.05) -> FloatArray:
        return self.route.path_xy(step_m)

    def radius_band_m(self) -> tuple[float, float]:
        return self.radius_m, self.radius_m


Motion = Annotated[ArcMotion | RouteMotion, Field(discriminator="kind")]
"""Any motion: `stops`, `duration_s`, `stop_intervals()`, `poses()`, `twist()`, `progress()`."""


def interpolate_drift(
    motion: ArcMotion | RouteMotion, deltas: NDArray[np.float64], t: FloatArray
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


def true_stop_poses(motion: ArcMotion | RouteMotion) -> list[Matrix4]:
    """True `T_world_base` of every stop."""
    return list(motion.poses(motion.stop_intervals()[:, 0]))
