"""Which scans go into a stop: only those wholly inside it, closed as the stream passes."""

from __future__ import annotations

import numpy as np

from pipeline.io.stop_clouds import StopClouds
from pipeline.io.stops import StopSpan

NS = 1_000_000_000
STOPS = (StopSpan(1 * NS, 3 * NS, np.eye(4)), StopSpan(5 * NS, 7 * NS, np.eye(4)))


def feed(clouds: StopClouds, until_s: float, *, close: bool = True) -> None:
    for k in range(int(until_s * 10) + 1):
        stamp = k * NS // 10
        points = np.full((4, 3), float(k)) if clouds.stop_index(stamp) is not None else None
        clouds.add_scan("lidar", stamp, points)
        if close:
            clouds.close_before(stamp - 2 * NS)


def test_only_scans_wholly_inside_are_kept_in_order() -> None:
    clouds = StopClouds(STOPS)
    feed(clouds, 8.0)
    clouds.close_all()

    first = clouds.closed[0]["lidar"]
    # Scans at 1.0 and 3.0 s are stamped inside but may reach outside by a period: dropped.
    assert first.scans == 19 and first.scans_touching == 21
    assert first.points is not None
    np.testing.assert_array_equal(np.unique(first.points[:, 0]), np.arange(11, 30))
    assert first.valid_points == 19 * 4
    assert clouds.closed[1]["lidar"].scans == 19


def test_stops_close_as_soon_as_the_stream_has_passed_them() -> None:
    clouds = StopClouds(STOPS)
    feed(clouds, 5.5)
    assert "lidar" in clouds.closed[0]  # closed at 5.1 s, two seconds past its end
    assert "lidar" not in clouds.closed[1]


def test_counting_mode_keeps_no_points() -> None:
    clouds = StopClouds(STOPS, keep_points=False)
    feed(clouds, 8.0)
    clouds.close_all()
    assert clouds.closed[0]["lidar"].points is None
    assert clouds.closed[0]["lidar"].valid_points == 19 * 4


def test_stop_index_and_period() -> None:
    clouds = StopClouds(STOPS)
    assert clouds.stop_index(0) is None
    assert clouds.stop_index(1 * NS) == 0
    assert clouds.stop_index(3 * NS) == 0
    assert clouds.stop_index(4 * NS) is None
    assert clouds.stop_index(7 * NS) == 1
    assert clouds.period_ns("lidar") == 0
    feed(clouds, 1.0, close=False)
    assert clouds.period_ns("lidar") == NS // 10


def test_a_scan_after_its_stop_closed_is_late_and_leaves_the_cloud_alone() -> None:
    clouds = StopClouds(STOPS)
    feed(clouds, 5.5)
    before = clouds.closed[0]["lidar"]

    clouds.add_scan("lidar", 2 * NS, np.zeros((4, 3)))
    clouds.close_all()

    assert clouds.closed[0]["lidar"] is before and before.scans == 19
    assert clouds.late == {"lidar": 1}


def test_scans_exactly_one_period_from_the_edges_are_inside() -> None:
    stop = StopSpan(1 * NS + 7, 1 * NS + 300_000_007, np.eye(4))  # 0.3 s, three periods
    clouds = StopClouds((stop,))
    for k in range(30):
        stamp = 7 + k * NS // 10
        points = np.ones((2, 3)) if clouds.stop_index(stamp) is not None else None
        clouds.add_scan("lidar", stamp, points)
    clouds.close_all()

    assert clouds.closed[0]["lidar"].scans == 2 and clouds.closed[0]["lidar"].scans_touching == 4


def test_stamps_a_rounding_error_off_their_grid_do_not_fall_off_the_edge() -> None:
    """A driver stamping from float seconds lands ~100 ns off the grid at today's epoch."""
    epoch = 1_700_000_000 * NS
    stop = StopSpan(epoch + NS, epoch + NS + 400_000_000, np.eye(4))
    off_grid = {11: -120, 13: +120}  # one period inside the edges, rounded outwards
    clouds = StopClouds((stop,))
    for k in range(40):
        stamp = epoch + k * NS // 10 + off_grid.get(k, 0)
        points = np.ones((2, 3)) if clouds.stop_index(stamp) is not None else None
        clouds.add_scan("lidar", stamp, points)
    clouds.close_all()

    assert clouds.closed[0]["lidar"].scans == 3
