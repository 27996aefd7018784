"""Header clocks: every LiDAR scan is put on the trajectory's clock before it is matched to a stop.

Stops are found on the trajectory's header stamps (odometry or `/tf`) and scans are matched to them
on their own header stamps: one clock, whatever the bag's log times say. A simulated run (Gazebo,
Isaac) stamps every header on simulated time while `ros2 bag record` logs the wall clock: one
offset between header stamps and log times, the same for every topic, so nothing needs doing. A
LiDAR whose own clock is off (a driver not synchronised by PTP or NTP, months behind) shows an
offset to the log time that differs from the trajectory's: its clock disagrees.

Decision: such a LiDAR is realigned, not refused. Its header stamps keep their spacing (the
driver's timing of each scan relative to the others) and are shifted by one constant, the
difference between its offset to the log time and the trajectory's. The log time is the one
clock every topic shares, so the shift places its scans where the recorder saw them, exact up to
the difference between the two topics' transport latencies. Refusing would reject a recording
whose data are usable because of a setting the user can only fix for the next one; the reader
says what it did in a warning instead. Offsets within the tolerance of the trajectory's are
latency, not another clock: those header stamps are kept as they are (the better time of two).

Offsets are medians of integer nanoseconds (a float64 loses the nanoseconds of an epoch), so a
recording on simulated time reads bit for bit like its wall-clock twin.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from rosbags.interfaces import Connection

from pipeline.io.source import OpenRecording, reading_errors, stamp_ns

NS = 1_000_000_000
PROBE_SCANS = 25
"""A LiDAR's clock and scan period are judged on its first scans (a few chunks, not the bag)."""

_Stamps = TypeVar("_Stamps", int, NDArray[np.int64])


def median_ns(values: ArrayLike) -> int:
    """The (upper) median of integer nanoseconds, exactly: no float64 rounding of large stamps."""
    array = np.asarray(values, dtype=np.int64)
    middle = len(array) // 2
    return int(np.partition(array, middle)[middle])


@dataclass(frozen=True)
class HeaderClock:
    """How a topic's header stamps relate to the bag's log times.

    `offset_ns`: median of `log time - header stamp`: transport latency, plus the difference of
    the clocks when the publisher's is not the recorder's (simulated time: about the wall clock's
    epoch). `stamped` is False when the publisher leaves every header stamp at zero: then the log
    time stands in for the stamp (a stamp of zero among others is kept: simulated time starts
    there).
    """

    offset_ns: int
    stamped: bool = True

    @classmethod
    def of(cls, header_ns: ArrayLike, log_ns: ArrayLike) -> HeaderClock:
        """The clock of messages with these header stamps and log times, (N,) ints each."""
        header = np.asarray(header_ns, dtype=np.int64)
        if not header.any():
            return cls(0, stamped=False)
        return cls(median_ns(np.asarray(log_ns, dtype=np.int64) - header))

    def stamp(self, header_ns: _Stamps, log_ns: _Stamps) -> _Stamps:
        """The time of a message (or of arrays of them) on this topic's header clock."""
        return header_ns if self.stamped else log_ns

    def describe(self) -> str:
        """`3.000 s behind its log times`, for messages."""
        if not self.stamped:
            return "unset (zero; their log times stand in)"
        lag = self.offset_ns / NS
        return f"{abs(lag):.3f} s {'behind' if lag >= 0 else 'ahead of'} their log times"


@dataclass(frozen=True)
class LidarClock:
    """A LiDAR topic's header clock, the shift (ns) that puts its stamps on the trajectory's
    clock (0 when they are on it already) and its scan period (ns, 0 with fewer than two scans)."""

    topic: str
    clock: HeaderClock
    shift_ns: int
    period_ns: int

    def on_trajectory_clock(self, header_ns: int, log_ns: int) -> int:
        """A scan's stamp on the trajectory's clock, from its header stamp and log time."""
        return self.clock.stamp(header_ns, log_ns) + self.shift_ns


def shift_onto(trajectory: HeaderClock, lidar: HeaderClock, tolerance_ns: int) -> int:
    """The shift from the LiDAR's header clock to the trajectory's: 0 when their offsets to the
    log time agree within `tolerance_ns` (latency), else the difference of the offsets."""
    difference = lidar.offset_ns - trajectory.offset_ns
    return difference if abs(difference) > tolerance_ns else 0


def probe_lidar_clocks(
    opened: OpenRecording,
    topics: Mapping[str, Sequence[Connection]],
    trajectory: HeaderClock,
    *,
    tolerance_ns: int,
    scans: int = PROBE_SCANS,
) -> dict[str, LidarClock]:
    """Each LiDAR topic's clock from its first `scans` scans; topics without scans are left out."""
    clocks: dict[str, LidarClock] = {}
    with reading_errors(opened.path, opened.storage):
        for topic, connections in topics.items():
            header, log = [], []
            for connection, log_ns, raw in itertools.islice(opened.messages(connections), scans):
                msg: Any = opened.deserialize(raw, connection)
                header.append(stamp_ns(msg.header))
                log.append(log_ns)
            if not header:
                continue
            clock = HeaderClock.of(header, log)
            stamps = np.sort(clock.stamp(np.asarray(header), np.asarray(log)))
            period = median_ns(np.diff(stamps)) if len(stamps) > 1 else 0
            clocks[topic] = LidarClock(
                topic, clock, shift_onto(trajectory, clock, tolerance_ns), period
            )
    return clocks


def clock_notes(
    trajectory_source: str, trajectory: HeaderClock, lidars: Iterable[LidarClock]
) -> list[str]:
    """What the user should hear about the clocks: disagreeing LiDARs, unset stamps."""
    notes = []
    if not trajectory.stamped:
        notes.append(
            f"the trajectory's ({trajectory_source}) header stamps are all zero; its log times "
            "stand in for them"
        )
    for lidar in lidars:
        if lidar.shift_ns:
            notes.append(
                f"clocks disagree: {lidar.topic}'s header stamps are "
                f"{lidar.clock.describe()}, the trajectory's ({trajectory_source}) "
                f"{trajectory.describe()}. The LiDAR's clock is not the trajectory's, so its "
                f"scans were shifted by {lidar.shift_ns / NS:+.3f} s onto the trajectory's "
                "clock through the log time they share (exact up to the topics' difference in "
                "transport latency); synchronise the LiDAR's clock (PTP or NTP) with the robot's"
            )
        elif not lidar.clock.stamped:
            notes.append(
                f"{lidar.topic}'s header stamps are all zero; its log times stand in for them"
            )
    return notes
