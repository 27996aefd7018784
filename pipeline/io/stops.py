"""Find the stops of a stop-and-go trajectory: spans where the base stands still long enough.

Speeds come from pose differences (odometry twists are often left empty, and `/tf` has none),
measured over a small centred window so that single-sample jitter does not split a stop. The
window blurs a stop's edges by half its width, so each run of still samples is widened again
over the samples next to it where the base still moved slower than the thresholds (sample to
sample), up to the window's reach: a stop's span is then the time the base stood still, and a
0.3 s stop keeps its scans. Times are integer nanoseconds throughout, so that no threshold has
a floating-point edge and a recording on simulated time finds the same stops as its wall-clock
twin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.io.trajectory import Trajectory
from pipeline.transforms import Matrix4

NS = 1_000_000_000


@dataclass(frozen=True)
class StopSpan:
    """A stop: the stamps (ns) of the first and last sample of its span, and the mean
    `T_odom_base` (4, 4) of its still samples."""

    t_start_ns: int
    t_end_ns: int
    T_odom_base: Matrix4

    @property
    def duration_ns(self) -> int:
        return self.t_end_ns - self.t_start_ns

    @property
    def duration_s(self) -> float:
        return self.duration_ns / NS


@dataclass(frozen=True)
class StillRuns:
    """Maximal runs of still samples and the spans they stand for, (R,) each.

    `first`, `last`: the run's still samples (inclusive indices into the trajectory). `start`,
    `end`: the first and last sample of its span, widened over the still steps next to it
    (`start <= first`, `last <= end`). `durations_ns`: from `start` to `end`.
    """

    first: NDArray[np.intp]
    last: NDArray[np.intp]
    start: NDArray[np.intp]
    end: NDArray[np.intp]
    durations_ns: NDArray[np.int64]

    @property
    def durations_s(self) -> NDArray[np.float64]:
        return self.durations_ns / NS


def _window(
    stamps_ns: NDArray[np.int64], window_s: float
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Per sample, the first and last samples within `window_s / 2` of it, or its two
    neighbours when the window holds no other sample."""
    n = len(stamps_ns)
    index = np.arange(n)
    half_ns = round(window_s * NS / 2)
    lo = np.searchsorted(stamps_ns, stamps_ns - half_ns, side="left")
    hi = np.searchsorted(stamps_ns, stamps_ns + half_ns, side="right") - 1
    alone = hi <= lo
    return (
        np.where(alone, np.maximum(index - 1, 0), lo),
        np.where(alone, np.minimum(index + 1, n - 1), hi),
    )


def _speeds_between(
    trajectory: Trajectory, lo: NDArray[np.intp], hi: NDArray[np.intp]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Linear (m/s) and angular (deg/s) speed from sample `lo` to sample `hi`, (K,) each."""
    dt = (trajectory.stamps_ns[hi] - trajectory.stamps_ns[lo]) / NS
    distance = np.linalg.norm(trajectory.translations[hi] - trajectory.translations[lo], axis=1)
    rotations = trajectory.rotations
    angle = np.degrees((rotations[lo].inv() * rotations[hi]).magnitude())
    return distance / dt, angle / dt


def speeds(
    trajectory: Trajectory, window_s: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Linear (m/s) and angular (deg/s) speed at each sample, (N,) each.

    Measured between the first and last samples within `window_s / 2` of it, or between its two
    neighbours when the window holds no other sample. Needs at least two samples.
    """
    return _speeds_between(trajectory, *_window(trajectory.stamps_ns, window_s))


def still_runs(
    trajectory: Trajectory,
    *,
    max_linear_speed: float,
    max_angular_speed_deg: float,
    speed_window_s: float,
    max_sample_gap_s: float,
) -> StillRuns:
    """Runs of consecutive still samples; a gap longer than `max_sample_gap_s` ends a run.

    A run's span reaches back from its first sample over every step (pair of consecutive
    samples) slower than the thresholds, but no further than that sample's speed window reached;
    likewise forward from its last. A step over a gap is never still.
    """
    stamps = trajectory.stamps_ns
    index = np.arange(len(stamps))
    lo, hi = _window(stamps, speed_window_s)
    linear, angular = _speeds_between(trajectory, lo, hi)
    still = np.flatnonzero((linear <= max_linear_speed) & (angular <= max_angular_speed_deg))
    gap_ns = round(max_sample_gap_s * NS)
    breaks = (np.diff(still) != 1) | (np.diff(stamps[still]) > gap_ns)
    first = still[np.r_[True, breaks]] if len(still) else still
    last = still[np.r_[breaks, True]] if len(still) else still

    step_linear, step_angular = _speeds_between(trajectory, index[:-1], index[1:])
    step_still = (
        (step_linear <= max_linear_speed)
        & (step_angular <= max_angular_speed_deg)
        & (np.diff(stamps) <= gap_ns)
    )
    # still_from[i] / still_to[i]: the farthest samples before / after i reached by still steps.
    still_from = np.maximum.accumulate(np.where(np.r_[True, ~step_still], index, 0))
    still_to = np.minimum.accumulate(
        np.where(np.r_[~step_still, True], index, len(index) - 1)[::-1]
    )[::-1]
    start = np.maximum(lo[first], still_from[first])
    end = np.minimum(hi[last], still_to[last])
    return StillRuns(first, last, start, end, stamps[end] - stamps[start])


def lasts_at_least(
    durations_ns: NDArray[np.int64], min_dwell_s: float, sample_period_ns: int
) -> NDArray[np.bool_]:
    """Which spans last `min_dwell_s`, to the resolution of their samples.

    Each sample stands for the period up to the next, so a span's samples last its duration
    plus one period: a stop that lasts exactly the minimum, whatever the phase of the samples
    against its edges, has that many. Half a period more is spared for stamps that were rounded
    or jitter, so that no stop falls off the threshold by a few nanoseconds.
    """
    min_ns = round(min_dwell_s * NS)
    kept: NDArray[np.bool_] = 2 * (durations_ns + sample_period_ns) + sample_period_ns >= 2 * min_ns
    return kept


def detect_stops(
    trajectory: Trajectory,
    *,
    max_linear_speed: float,
    max_angular_speed_deg: float,
    min_dwell_s: float,
    speed_window_s: float,
    max_sample_gap_s: float,
) -> tuple[StopSpan, ...]:
    """The still spans lasting at least `min_dwell_s`, in time order, with the mean pose of
    their still samples."""
    runs = still_runs(
        trajectory,
        max_linear_speed=max_linear_speed,
        max_angular_speed_deg=max_angular_speed_deg,
        speed_window_s=speed_window_s,
        max_sample_gap_s=max_sample_gap_s,
    )
    stamps = trajectory.stamps_ns
    period_ns = int(np.median(np.diff(stamps))) if len(stamps) > 1 else 0
    keep = lasts_at_least(runs.durations_ns, min_dwell_s, period_ns)
    return tuple(
        StopSpan(int(stamps[start]), int(stamps[end]), trajectory.mean_pose(int(first), int(last)))
        for first, last, start, end in zip(
            runs.first[keep], runs.last[keep], runs.start[keep], runs.end[keep], strict=True
        )
    )
