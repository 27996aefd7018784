"""Header clocks: offsets to the log time, disagreement between topics, and the shift between."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.io.clocks import HeaderClock, LidarClock, clock_notes, median_ns, shift_onto

NS = 1_000_000_000
WALL_NS = 1_700_000_000 * NS


def test_median_is_exact_at_the_epoch() -> None:
    values = np.array([WALL_NS + 3, WALL_NS + 1, WALL_NS + 2, WALL_NS + 1_000_000])
    assert int(np.median(values)) == WALL_NS  # float64 loses the nanoseconds
    assert median_ns(values) == WALL_NS + 3


def test_offset_of_simulated_time_and_latency() -> None:
    header = np.arange(10, dtype=np.int64) * NS // 10  # simulated time from 0
    latency = np.array([3, 2, 4, 3, 250, 3, 2, 3, 4, 3]) * 1_000_000  # one late message
    clock = HeaderClock.of(header, WALL_NS + header + latency)
    assert clock == HeaderClock(WALL_NS + 3_000_000)
    assert clock.stamp(5, 7) == 5


def test_all_zero_stamps_are_unset_and_the_log_time_stands_in() -> None:
    clock = HeaderClock.of([0, 0, 0], [WALL_NS, WALL_NS + 1, WALL_NS + 2])
    assert clock == HeaderClock(0, stamped=False)
    assert clock.stamp(0, WALL_NS + 1) == WALL_NS + 1
    # A stamp of zero among others is simulated time's first instant, not an unset stamp.
    assert HeaderClock.of([0, 100], [WALL_NS, WALL_NS + 100]).stamped


@pytest.mark.parametrize(
    ("lidar_offset_ns", "shift_ns"),
    [
        (WALL_NS + 40_000_000, 0),  # 40 ms more latency than the trajectory: one clock
        (WALL_NS - 450_000_000, 0),
        (WALL_NS + 600_000_000, 600_000_000),
        (WALL_NS + 120 * 86_400 * NS, 120 * 86_400 * NS),  # four months behind
    ],
)
def test_a_lidar_is_shifted_only_when_its_clock_disagrees(
    lidar_offset_ns: int, shift_ns: int
) -> None:
    trajectory = HeaderClock(WALL_NS)
    assert shift_onto(trajectory, HeaderClock(lidar_offset_ns), 500_000_000) == shift_ns


def test_notes_name_the_disagreeing_lidar_and_the_shift() -> None:
    lidars = [
        LidarClock("/front/points", HeaderClock(120 * 86_400 * NS), 120 * 86_400 * NS, NS // 10),
        LidarClock("/rear/points", HeaderClock(2_000_000), 0, NS // 10),
    ]

    notes = clock_notes("odometry:/odom", HeaderClock(1_000_000), lidars)

    assert notes == [
        "clocks disagree: /front/points's header stamps are 10368000.000 s behind their log "
        "times, the trajectory's (odometry:/odom) 0.001 s behind their log times. The LiDAR's "
        "clock is not the trajectory's, so its scans were shifted by +10368000.000 s onto the "
        "trajectory's clock through the log time they share (exact up to the topics' difference "
        "in transport latency); synchronise the LiDAR's clock (PTP or NTP) with the robot's"
    ]
