"""Routines as a base drives them: where the stops lie, speed limits kept, still at every stop."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.synth.motion import RouteMotion
from pipeline.synth.routines import (
    Speeds,
    figure_eight,
    figure_eight_stop_count,
    lane,
    lane_stop_count,
    loop,
    loop_stop_count,
    rotate_in_place,
)

SPEEDS = Speeds(drive_mps=0.6, turn_dps=45.0)


def _stop_xy_yaw(motion: RouteMotion) -> tuple[np.ndarray, np.ndarray]:
    poses = motion.poses(motion.stop_intervals()[:, 0])
    return poses[:, :2, 3], np.degrees(np.arctan2(poses[:, 1, 0], poses[:, 0, 0]))


def _assert_drives_like_a_base(motion: RouteMotion, speeds: Speeds) -> None:
    """Peak speeds within the limits, still during every stop, heading along the path."""
    t = np.linspace(0.0, motion.duration_s, 20_001)
    linear, angular = motion.twist(t)
    assert np.abs(linear[:, 0]).max() <= speeds.drive_mps * (1 + 1e-9)
    assert np.degrees(np.abs(angular[:, 2])).max() <= speeds.turn_dps * (1 + 1e-9)
    for start, end in motion.stop_intervals():
        inside = (t >= start) & (t <= end)
        assert np.all(linear[inside] == 0) and np.all(angular[inside] == 0)
    poses = motion.poses(t)
    velocity = np.gradient(poses[:, :2, 3], t, axis=0)
    heading = poses[:, :2, 0]
    sideways = heading[:, 0] * velocity[:, 1] - heading[:, 1] * velocity[:, 0]
    assert np.abs(sideways).max() < 1e-3
    np.testing.assert_allclose(np.sum(heading * velocity, axis=1), linear[:, 0], atol=1e-3)


def test_rotate_in_place_turns_on_the_spot() -> None:
    motion = rotate_in_place(30.0, [1.0, 0.5, 2.0, 0.4], SPEEDS)
    xy, yaw = _stop_xy_yaw(motion)
    np.testing.assert_allclose(xy, 0.0, atol=1e-12)
    np.testing.assert_allclose(yaw, [0, 30, 60, 90], atol=1e-9)
    np.testing.assert_allclose(np.diff(motion.stop_intervals(), axis=1)[:, 0], [1.0, 0.5, 2.0, 0.4])
    _assert_drives_like_a_base(motion, SPEEDS)


@pytest.mark.parametrize("left", [True, False])
def test_loop_stops_at_corners_and_along_the_sides(left: bool) -> None:
    sides, spacing = (3.0, 1.2), 1.0
    count = loop_stop_count(sides, spacing)
    motion = loop(sides, spacing, [0.6] * count, SPEEDS, left=left)
    assert motion.stops == count == 2 * (3 + 2) + 1 + 3
    xy, yaw = _stop_xy_yaw(motion)
    sign = 1.0 if left else -1.0
    corners = np.array([[0, 0], [3.0, 0], [3.0, sign * 1.2], [0, sign * 1.2]])
    for corner in corners:
        assert np.min(np.linalg.norm(xy - corner, axis=1)) < 1e-9
    np.testing.assert_allclose(xy[-1], [0, 0], atol=1e-9)
    assert np.linalg.norm(np.diff(xy, axis=0), axis=1).max() <= spacing + 1e-9
    assert set(np.round(np.mod(yaw, 360.0)).astype(int)) == (
        {0, 90, 180, 270} if left else {0, 270, 180, 90}
    )
    _assert_drives_like_a_base(motion, SPEEDS)


def test_figure_eight_drives_two_circles_forward() -> None:
    motion = figure_eight(1.2, 8, [1.0] * figure_eight_stop_count(8), SPEEDS)
    xy, _ = _stop_xy_yaw(motion)
    np.testing.assert_allclose(xy[[0, 8, 16]], 0.0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(xy[1:8] - [0, 1.2], axis=1), 1.2, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(xy[9:16] - [0, -1.2], axis=1), 1.2, atol=1e-9)
    _assert_drives_like_a_base(motion, SPEEDS)


def test_lane_goes_down_turns_round_and_comes_back() -> None:
    count = lane_stop_count(2.5, 1.0)
    motion = lane(2.5, 1.0, [0.8] * count, SPEEDS)
    xy, yaw = _stop_xy_yaw(motion)
    assert count == 8
    np.testing.assert_allclose(xy[3], [2.5, 0], atol=1e-9)
    np.testing.assert_allclose(xy[4], [2.5, 0], atol=1e-9)
    assert abs(abs(yaw[4]) - 180.0) < 1e-9 and abs(yaw[3]) < 1e-9
    np.testing.assert_allclose(xy[-1], [0, 0], atol=1e-9)
    _assert_drives_like_a_base(motion, SPEEDS)


def test_moves_take_as_long_as_the_speed_limits_allow() -> None:
    motion = lane(2.0, 2.0, [1.0] * 4, SPEEDS)
    legs = np.diff(motion.stop_intervals()[:, 0]) - 1.0
    np.testing.assert_allclose(legs, [1.875 * 2.0 / 0.6, 1.875 * 180 / 45.0, 1.875 * 2.0 / 0.6])
    arc = SPEEDS.arc(90.0, radius_m=2.0)
    assert arc.duration_s == pytest.approx(1.875 * math.pi / 0.6)


def test_a_dwell_per_stop_is_required() -> None:
    with pytest.raises(ConfigError, match=r"loop routine has 14 stops but 3 dwell times"):
        loop((3.0, 1.2), 1.0, [1.0] * 3, SPEEDS)


def test_path_points_follow_the_route_and_bound_its_distance_from_the_origin() -> None:
    motion = loop((2.0, 1.0), 1.0, [1.0] * loop_stop_count((2.0, 1.0), 1.0), SPEEDS)
    xy = motion.path_xy(step_m=0.05)
    on_sides = np.minimum.reduce(
        [np.abs(xy[:, 1]), np.abs(xy[:, 1] - 1.0), np.abs(xy[:, 0]), np.abs(xy[:, 0] - 2.0)]
    )
    assert on_sides.max() < 1e-9 and np.linalg.norm(np.diff(xy, axis=0), axis=1).max() <= 0.05
    low, high = motion.radius_band_m()
    assert low == pytest.approx(0.0, abs=1e-9) and high == pytest.approx(math.hypot(2.0, 1.0))
