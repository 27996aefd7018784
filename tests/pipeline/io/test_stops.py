"""Stop detection on synthetic trajectories with known still spans."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.io.stops import detect_stops, speeds
from pipeline.io.trajectory import Trajectory
from pipeline.transforms import pose_difference

SETTINGS = {
    "max_linear_speed": 0.02,
    "max_angular_speed_deg": 1.0,
    "min_dwell_s": 1.0,
    "speed_window_s": 0.2,
    "max_sample_gap_s": 0.5,
}


def stop_and_go(t: np.ndarray, *, noise_m: float = 0.0, seed: int = 0) -> Trajectory:
    """Still 0-2 s at the origin; 2-3 s drive 0.5 m along x turning 30 deg; then still."""
    progress = np.clip(t - 2.0, 0.0, 1.0)
    translations = np.c_[0.5 * progress, np.zeros_like(t), np.zeros_like(t)]
    translations += np.random.default_rng(seed).normal(0, noise_m, translations.shape)
    quats = Rotation.from_euler("z", 30.0 * progress[:, None], degrees=True).as_quat()
    return Trajectory.from_arrays((t * 1e9).round().astype(np.int64), translations, quats, "test")


T50 = np.arange(0.0, 5.5, 0.02)


def test_two_stops_with_their_spans_and_mean_poses() -> None:
    stops = detect_stops(stop_and_go(T50), **SETTINGS)

    assert len(stops) == 2
    # The centred window marks samples within half a window of motion as moving.
    assert stops[0].t_start_ns == 0 and stops[0].t_end_ns * 1e-9 == pytest.approx(1.9)
    assert stops[1].t_start_ns * 1e-9 == pytest.approx(3.1)
    assert stops[1].t_end_ns * 1e-9 == pytest.approx(5.48)
    assert pose_difference(stops[0].T_odom_base, np.eye(4)) == pytest.approx((0.0, 0.0), abs=1e-9)
    distance, angle = pose_difference(stops[1].T_odom_base, np.eye(4))
    assert distance == pytest.approx(0.5) and angle == pytest.approx(30.0)


def test_speeds_while_moving() -> None:
    linear, angular = speeds(stop_and_go(T50), 0.2)
    moving = (T50 > 2.2) & (T50 < 2.8)
    np.testing.assert_allclose(linear[moving], 0.5, rtol=1e-6)
    np.testing.assert_allclose(angular[moving], 30.0, rtol=1e-6)
    assert (linear[T50 < 1.8] == 0).all()


def test_turning_in_place_is_motion() -> None:
    t = np.arange(0.0, 5.0, 0.02)
    quats = Rotation.from_euler("z", 10.0 * np.clip(t - 2.0, 0, 1)[:, None], degrees=True).as_quat()
    trajectory = Trajectory.from_arrays(
        (t * 1e9).astype(np.int64), np.zeros((len(t), 3)), quats, ""
    )
    assert len(detect_stops(trajectory, **SETTINGS)) == 2


def test_window_damps_odometry_jitter() -> None:
    jittery = stop_and_go(T50, noise_m=0.0008)
    assert len(detect_stops(jittery, **SETTINGS)) == 2
    assert len(detect_stops(jittery, **{**SETTINGS, "speed_window_s": 0.0})) != 2


def test_gap_in_the_trajectory_splits_a_stop() -> None:
    t = T50[(T50 < 0.8) | (T50 > 1.6)]  # 0.8 s without odometry inside the first still span
    stops = detect_stops(stop_and_go(t), **{**SETTINGS, "min_dwell_s": 0.2})
    assert [round(s.t_start_ns * 1e-9, 2) for s in stops] == [0.0, 1.62, 3.1]


def test_short_still_span_is_no_stop() -> None:
    stops = detect_stops(stop_and_go(T50), **{**SETTINGS, "min_dwell_s": 2.0})
    assert [round(s.t_start_ns * 1e-9, 2) for s in stops] == [3.1]
