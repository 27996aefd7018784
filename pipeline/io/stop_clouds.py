"""Accumulate each LiDAR's scans that lie wholly inside a stop, one stop at a time.

A scan is stamped at its start or its end depending on the driver, so "wholly inside" means
`stamp - period >= stop start` and `stamp + period <= stop end`, with the period estimated from
the LiDAR's own stamps. Stamps are integer nanoseconds on the trajectory's clock (see `clocks`),
and the test allows 1 % of the period, so a scan one period from a stop's edge is inside even
when its driver rounded its stamp from float seconds (~100 ns off at today's epoch). A stop is
concatenated as soon as the stream has passed it, so memory holds the kept clouds plus one stop's
worth of candidate scans, never the whole recording; a scan of a stop already closed is counted
late and left out.
"""

from __future__ import annotations

import bisect
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.io.stops import StopSpan

_EDGE_TOLERANCE_DIVISOR = 100  # a scan may reach past a stop's edge by 1 % of its period


@dataclass
class _Candidate:
    stamp_ns: int
    points: NDArray[np.floating[Any]] | None
    valid: int


@dataclass
class StopCloud:
    """One LiDAR in one stop: the kept scans' points (None when only counting) and counts."""

    points: NDArray[np.float64] | None
    valid_points: int
    scans: int
    scans_touching: int
    """Scans stamped inside the stop, kept or not (to explain an empty cloud)."""
    scan_sizes: tuple[int, ...] = ()
    """Points of each kept scan, in the order they are concatenated in `points`."""


class StopClouds:
    """Candidate scans per stop and LiDAR frame, closed into `StopCloud`s in time order.

    `closed[k][frame]` is stop `k`'s cloud of that LiDAR once the stop is closed; a LiDAR with
    no scan stamped inside the stop has no entry. With `keep_points=False` only counts are kept.
    `late[frame]`: scans that arrived after their stop was closed (left out of it).
    """

    def __init__(self, stops: Sequence[StopSpan], *, keep_points: bool = True) -> None:
        self.stops = tuple(stops)
        self.keep_points = keep_points
        self.closed: list[dict[str, StopCloud]] = [{} for _ in self.stops]
        self._starts = [stop.t_start_ns for stop in self.stops]
        self._stamps: dict[str, list[int]] = defaultdict(list)
        self._pending: dict[int, dict[str, list[_Candidate]]] = {}
        self._done: set[int] = set()
        self.late: dict[str, int] = defaultdict(int)

    def stop_index(self, stamp_ns: int) -> int | None:
        """The stop whose span holds `stamp_ns`, if any: only such scans need decoding."""
        index = bisect.bisect_right(self._starts, stamp_ns) - 1
        if index >= 0 and stamp_ns <= self.stops[index].t_end_ns:
            return index
        return None

    def add_scan(self, frame: str, stamp_ns: int, points: NDArray[np.floating[Any]] | None) -> None:
        """Record every scan's stamp; `points` (decoded if `stop_index` found a stop) wait there."""
        self._stamps[frame].append(stamp_ns)
        index = self.stop_index(stamp_ns)
        if index is None or points is None:
            return
        if index in self._done:
            self.late[frame] += 1
            return
        kept = points if self.keep_points else None
        per_frame = self._pending.setdefault(index, {})
        per_frame.setdefault(frame, []).append(_Candidate(stamp_ns, kept, len(points)))

    def close_before(self, t_ns: int) -> None:
        """Close every pending stop that ended before `t_ns`: no scan of it can still arrive."""
        for index in sorted(self._pending):
            if self.stops[index].t_end_ns < t_ns:
                self._close(index)

    def close_all(self) -> None:
        for index in sorted(self._pending):
            self._close(index)

    def period_ns(self, frame: str) -> int:
        """Median spacing of the frame's scan stamps so far (0 with fewer than two scans)."""
        stamps = np.sort(np.asarray(self._stamps.get(frame, ()), dtype=np.int64))
        return int(np.median(np.diff(stamps))) if len(stamps) > 1 else 0

    def _close(self, index: int) -> None:
        stop = self.stops[index]
        self._done.add(index)
        for frame, candidates in self._pending.pop(index).items():
            reach = self.period_ns(frame) - self.period_ns(frame) // _EDGE_TOLERANCE_DIVISOR
            inside = [
                c
                for c in candidates
                if c.stamp_ns - reach >= stop.t_start_ns and c.stamp_ns + reach <= stop.t_end_ns
            ]
            points: NDArray[np.float64] | None = None
            sizes: tuple[int, ...] = ()
            if self.keep_points:
                arrays = [c.points for c in inside if c.points is not None]
                # Scans wait in their stored type (float32, half the memory) and become
                # float64 in this one copy.
                points = np.concatenate(arrays, dtype=np.float64) if arrays else np.empty((0, 3))
                sizes = tuple(len(a) for a in arrays)
            self.closed[index][frame] = StopCloud(
                points, sum(c.valid for c in inside), len(inside), len(candidates), sizes
            )
