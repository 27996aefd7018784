"""Stop-and-go motion: still at stops, smooth between them, odometry error constant per stop."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from pipeline.synth.motion import Arc, ArcMotion, RouteMotion, Straight, interpolate_drift
from pipeline.synth.perturbation import PerturbationBounds, random_perturbation
from pipeline.transforms import pose_difference


def test_robot_is_still_during_stops_and_reaches_each_stop_heading() -> None:
    motion = ArcMotion(stops=4, radius_m=2.0, step_deg=30.0, dwell_s=1.0, move_s=0.5)
    for j, (start, end) in enumerate(motion.stop_intervals()):
        t = np.linspace(start, end, 7)
        poses = motion.poses(t)
        np.testing.assert_allclose(poses, np.broadcast_to(poses[0], poses.shape), atol=1e-12)
        linear, angular = motion.twist(t)
        assert np.all(linear == 0) and np.all(angular == 0)
        yaw = np.degrees(np.arctan2(poses[0, 1, 0], poses[0, 0, 0]))
        assert abs(yaw - 30.0 * j) < 1e-9
        assert abs(np.hypot(*poses[0, :2, 3]) - 2.0) < 1e-12


def test_moving_robot_heads_along_the_arc() -> None:
    motion = ArcMotion(stops=2, radius_m=1.5, step_deg=40.0, dwell_s=1.0, move_s=1.0)
    t = np.array([1.5, 1.5 + 1e-6])
    poses = motion.poses(t)
    velocity = (poses[1, :3, 3] - poses[0, :3, 3]) / 1e-6
    linear, angular = motion.twist(t[:1])
    np.testing.assert_allclose(poses[0, :3, :3].T @ velocity, linear[0], atol=1e-4)
    assert angular[0, 2] > 0


def test_odometry_drift_is_constant_in_a_stop_and_bounded_between() -> None:
    motion = ArcMotion(stops=3, dwell_s=1.0, move_s=1.0)
    rng = np.random.default_rng(0)
    bounds = PerturbationBounds(translation_m=0.2, rotation_deg=3.0)
    deltas = np.stack([random_perturbation(rng, bounds) for _ in range(3)])
    in_stop = interpolate_drift(motion, deltas, np.array([2.0, 2.5, 3.0]))
    np.testing.assert_allclose(in_stop, np.broadcast_to(deltas[1], in_stop.shape), atol=1e-12)
    moving = interpolate_drift(motion, deltas, np.linspace(1.0, 2.0, 50))
    sizes = np.array([pose_difference(np.eye(4), d) for d in moving])
    assert sizes[:, 0].max() <= 0.2 + 1e-12 and sizes[:, 1].max() <= 3.0 + 1e-9


def test_arc_motion_is_the_route_of_its_stops() -> None:
    motion = ArcMotion(stops=5, radius_m=1.5, step_deg=-25.0, start_deg=10.0, dwell_s=0.7)
    t = np.linspace(-0.2, motion.duration_s + 0.2, 777)
    j, s, _ = motion.progress(t)
    theta = np.radians(10.0 - 25.0 * (j + s))
    poses = motion.poses(t)
    np.testing.assert_allclose(poses[:, 0, 3], 1.5 * np.sin(theta), atol=1e-12)
    np.testing.assert_allclose(poses[:, 1, 3], -1.5 * np.cos(theta), atol=1e-12)
    np.testing.assert_allclose(motion.stop_intervals()[:, 0], np.arange(5) * 1.2, atol=1e-12)
    assert motion.route.duration_s == pytest.approx(motion.duration_s)


def test_route_needs_one_leg_between_each_pair_of_stops() -> None:
    with pytest.raises(ValidationError, match=r"a route with 3 stops needs 2 legs"):
        RouteMotion(dwell_s=(1.0, 1.0, 1.0), legs=((Straight(distance_m=1, duration_s=1),),))


def test_wheel_travel_counts_distance_and_turning() -> None:
    route = RouteMotion(
        dwell_s=(1.0, 1.0, 1.0),
        legs=(
            (Straight(distance_m=-2.0, duration_s=3.0),),
            (Arc(radius_m=1.0, angle_deg=90.0, duration_s=3.0),),
        ),
    )
    np.testing.assert_allclose(route.travel_m(0.25), [0.0, 2.0, 2.0 + 1.25 * math.pi / 2])
    # Reversing: the base drives backwards, still heading along +x.
    end = route.poses(route.stop_intervals()[1:2, 0])[0]
    np.testing.assert_allclose(end[:2, 3], [-2.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(end[:3, :3], np.eye(3), atol=1e-12)
