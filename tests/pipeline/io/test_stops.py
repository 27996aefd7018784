"""Stop detection on synthetic trajectories with known still spans, on any clock."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.io.config import StopDetectionConfig
from pipeline.io.stops import detect_stops, lasts_at_least, speeds, still_runs
from pipeline.io.trajectory import Trajectory
from pipeline.transforms import pose_difference

NS = 1_000_000_000
EPOCH_NS = 1_700_000_000 * NS  # a wall clock; simulated time starts at 0

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


def routine(
    stops: int,
    dwell_ns: int,
    *,
    t0_ns: int = 0,
    move_ns: int = NS,
    period_ns: int = 20_000_000,
    smooth: bool = False,
) -> Trajectory:
    """`stops` stops of `dwell_ns` each, 0.3 m and 20 deg apart, sampled every `period_ns` from
    `t0_ns` (stop k starts at `t0_ns + k * (dwell_ns + move_ns)`). Moves at constant speed, or
    with a minimum-jerk profile (zero speed and acceleration at both ends) when `smooth`."""
    cycle = dwell_ns + move_ns
    n = ((stops - 1) * cycle + dwell_ns) // period_ns + 1
    rel = np.arange(n, dtype=np.int64) * period_ns
    k = np.minimum(rel // cycle, stops - 1)
    tau = np.clip((rel - k * cycle - dwell_ns) / move_ns, 0.0, 1.0)
    tau = np.where(k == stops - 1, 0.0, tau)
    progress = k + (tau**3 * (10 - 15 * tau + 6 * tau**2) if smooth else tau)
    translations = np.c_[0.3 * progress, np.zeros(n), np.zeros(n)]
    quats = Rotation.from_euler("z", 20.0 * progress[:, None], degrees=True).as_quat()
    return Trajectory.from_arrays(t0_ns + rel, translations, quats, "test")


def test_two_stops_with_their_spans_and_mean_poses() -> None:
    stops = detect_stops(stop_and_go(T50), **SETTINGS)

    assert len(stops) == 2
    # The speed window blurs the edges by its half; the still steps next to them give it back.
    assert stops[0].t_start_ns == 0 and stops[0].t_end_ns == 2 * NS
    assert stops[1].t_start_ns == 3 * NS
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
    # Neither span reaches over the gap.
    assert [round(s.t_start_ns * 1e-9, 2) for s in stops] == [0.0, 1.62, 3.0]
    assert round(stops[0].t_end_ns * 1e-9, 2) == 0.78


def test_short_still_span_is_no_stop() -> None:
    stops = detect_stops(stop_and_go(T50), **{**SETTINGS, "min_dwell_s": 2.1})
    assert [round(s.t_start_ns * 1e-9, 2) for s in stops] == [3.0]


@pytest.mark.parametrize("t0_ns", [0, 1000 * NS, EPOCH_NS + 123_456_789])
@pytest.mark.parametrize("dwell_s", [0.3, 0.4, 0.8, 1.0])
def test_stops_lasting_exactly_the_minimum_are_all_found(t0_ns: int, dwell_s: float) -> None:
    trajectory = routine(12, round(dwell_s * NS), t0_ns=t0_ns)

    stops = detect_stops(trajectory, **{**SETTINGS, "min_dwell_s": dwell_s})

    assert len(stops) == 12
    assert [s.duration_ns for s in stops] == [round(dwell_s * NS)] * 12
    assert stops[3].t_start_ns == t0_ns + 3 * (round(dwell_s * NS) + NS)
    # Two sample periods more than the stops last, and they are too short.
    longer = dwell_s + 0.04
    assert detect_stops(trajectory, **{**SETTINGS, "min_dwell_s": longer}) == ()


def test_stamps_rounded_from_float_seconds_keep_stops_of_exactly_one_second() -> None:
    """Recorders stamp from float seconds: at the epoch a stamp is off its grid by ~100 ns."""
    t0_ns = EPOCH_NS + 123_456_789
    exact = routine(8, NS, t0_ns=t0_ns)
    seconds = t0_ns / NS + (exact.stamps_ns - t0_ns) / NS
    rounded = Trajectory.from_arrays(
        np.round(seconds * NS).astype(np.int64),
        exact.translations,
        exact.rotations_xyzw,
        "float stamps",
    )
    assert (rounded.stamps_ns != exact.stamps_ns).any()

    assert len(detect_stops(rounded, **SETTINGS)) == 8


def test_default_config_keeps_stops_of_0_3_s() -> None:
    defaults = StopDetectionConfig().model_dump(exclude={"min_scan_periods"})
    assert len(detect_stops(routine(6, 300_000_000), **defaults)) == 6
    assert detect_stops(routine(6, 250_000_000), **defaults) == ()


def test_simulated_clock_finds_the_same_stops_as_the_wall_clock() -> None:
    settings = {**SETTINGS, "min_dwell_s": 0.5}
    wall = detect_stops(routine(5, 700_000_000, t0_ns=EPOCH_NS, smooth=True), **settings)
    simulated = detect_stops(routine(5, 700_000_000, t0_ns=0, smooth=True), **settings)

    assert len(wall) == len(simulated) == 5
    for a, b in zip(wall, simulated, strict=True):
        assert (a.t_start_ns - EPOCH_NS, a.t_end_ns - EPOCH_NS) == (b.t_start_ns, b.t_end_ns)
        np.testing.assert_array_equal(a.T_odom_base, b.T_odom_base)


def test_smooth_ramps_widen_a_stop_only_where_the_base_was_still() -> None:
    dwell_ns, period_ns = 600_000_000, 20_000_000
    trajectory = routine(4, dwell_ns, period_ns=period_ns, smooth=True)
    settings = {k: v for k, v in SETTINGS.items() if k != "min_dwell_s"}

    runs = still_runs(trajectory, **settings)
    stops = detect_stops(trajectory, **{**SETTINGS, "min_dwell_s": 0.3})

    assert len(stops) == 4
    cycle = dwell_ns + NS
    stamps = list(trajectory.stamps_ns)
    for k, stop in enumerate(stops):
        true_start, true_end = k * cycle, k * cycle + dwell_ns
        # Wider than the true stop by less than the window's half, where the base barely moved.
        assert true_start - 100_000_000 < stop.t_start_ns <= true_start
        assert true_end <= stop.t_end_ns < true_end + 100_000_000
        for edge in (stop.t_start_ns, stop.t_end_ns):
            sample = stamps.index(edge)
            T_odom_base = trajectory.mean_pose(sample, sample)
            distance, angle = pose_difference(T_odom_base, stop.T_odom_base)
            assert distance < 0.001 and angle < 0.05
    # ... and wider than the samples the speed window found still.
    assert (runs.start[1:] < runs.first[1:]).all() and (runs.end[:-1] > runs.last[:-1]).all()


def test_lasts_at_least_counts_a_period_per_sample_and_spares_half_of_one() -> None:
    # 50 samples at 50 Hz (a 1.0 s stop between samples) span 0.98 s; 49 span 0.96 s.
    durations = np.array([980_000_000, 979_999_997, 970_000_000, 969_999_999], dtype=np.int64)
    np.testing.assert_array_equal(
        lasts_at_least(durations, 1.0, 20_000_000), [True, True, True, False]
    )


@pytest.mark.parametrize("phase_ns", [0, 1_000_000, 7_000_000, 19_000_000])
def test_stops_of_exactly_one_second_between_samples_are_kept(phase_ns: int) -> None:
    exact = routine(6, NS, period_ns=1_000_000)  # a stop's edges fall between 50 Hz samples
    samples = np.flatnonzero((exact.stamps_ns - phase_ns) % 20_000_000 == 0)
    trajectory = Trajectory.from_arrays(
        exact.stamps_ns[samples],
        exact.translations[samples],
        exact.rotations_xyzw[samples],
        "50 Hz",
    )
    assert len(detect_stops(trajectory, **SETTINGS)) == 6
