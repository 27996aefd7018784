"""Find the stops of a stop-and-go trajectory: spans where the base stands still long enough.

Speeds come from pose differences (odometry twists are often left empty, and `/tf` has none),
measured over a small centred window so that single-sample jitter does not split a stop.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.io.trajectory import Trajectory
from pipeline.transforms import Matrix4


@dataclass(frozen=True)
class StopSpan:
    """A stop: first and last still sample (ns, inclusive) and the mean `T_odom_base` (4, 4)."""

    t_start_ns: int
    t_end_ns: int
    T_odom_base: Matrix4

    @property
    def duration_s(self) -> float:
        return (self.t_end_ns - self.t_start_ns) * 1e-9


@dataclass(frozen=True)
class StillRuns:
    """Maximal runs of still samples, as inclusive index pairs into the trajectory, (R,) each."""

    first: NDArray[np.intp]
    last: NDArray[np.intp]
    durations_s: NDArray[np.float64]


def speeds(
    trajectory: Trajectory, window_s: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Linear (m/s) and angular (deg/s) speed at each sample, (N,) each.

    Measured between the first and last samples within `window_s / 2` of it, or between its two
    neighbours when the window holds no other sample. Needs at least two samples.
    """
    t = trajectory.seconds
    n = len(t)
    index = np.arange(n)
    lo = np.searchsorted(t, t - window_s / 2, side="left")
    hi = np.searchsorted(t, t + window_s / 2, side="right") - 1
    alone = hi <= lo
    lo = np.where(alone, np.maximum(index - 1, 0), lo)
    hi = np.where(alone, np.minimum(index + 1, n - 1), hi)
    dt = t[hi] - t[lo]
    distance = np.linalg.norm(trajectory.translations[hi] - trajectory.translations[lo], axis=1)
    rotations = trajectory.rotations
    angle = np.degrees((rotations[lo].inv() * rotations[hi]).magnitude())
    return distance / dt, angle / dt


def still_runs(
    trajectory: Trajectory,
    *,
    max_linear_speed: float,
    max_angular_speed_deg: float,
    speed_window_s: float,
    max_sample_gap_s: float,
) -> StillRuns:
    """Runs of consecutive still samples; a gap longer than `max_sample_gap_s` ends a run."""
    linear, angular = speeds(trajectory, speed_window_s)
    still = np.flatnonzero((linear <= max_linear_speed) & (angular <= max_angular_speed_deg))
    t = trajectory.seconds
    breaks = (np.diff(still) != 1) | (np.diff(t[still]) > max_sample_gap_s)
    first = still[np.r_[True, breaks]] if len(still) else still
    last = still[np.r_[breaks, True]] if len(still) else still
    return StillRuns(first, last, t[last] - t[first])


def detect_stops(
    trajectory: Trajectory,
    *,
    max_linear_speed: float,
    max_angular_speed_deg: float,
    min_dwell_s: float,
    speed_window_s: float,
    max_sample_gap_s: float,
) -> tuple[StopSpan, ...]:
    """The still runs lasting at least `min_dwell_s`, in time order, with their mean pose."""
    runs = still_runs(
        trajectory,
        max_linear_speed=max_linear_speed,
        max_angular_speed_deg=max_angular_speed_deg,
        speed_window_s=speed_window_s,
        max_sample_gap_s=max_sample_gap_s,
    )
    keep = runs.durations_s >= min_dwell_s
    return tuple(
        StopSpan(
            int(trajectory.stamps_ns[first]),
            int(trajectory.stamps_ns[last]),
            trajectory.mean_pose(int(first), int(last)),
        )
        for first, last in zip(runs.first[keep], runs.last[keep], strict=True)
    )
