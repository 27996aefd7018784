"""Randomised scenarios: deterministic per seed, every factor inside its declared range, every
class reachable, drift growing along the path."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest

import pipeline.synth.random_scenario as module
from pipeline.errors import ConfigError
from pipeline.synth.lidar_models import Mid70, Mid360, SpinningLidar
from pipeline.synth.motion import Arc, RouteMotion
from pipeline.synth.random_scenario import (
    CLOCKS,
    RANGES,
    clock_kind,
    random_scenario,
    scenario_classes,
)
from pipeline.synth.scenarios import ScenarioSpec, WorldKind
from pipeline.synth.simulate import make_world
from pipeline.transforms import pose_difference

SEEDS = range(0, 240)


@cache
def _spec(seed: int) -> ScenarioSpec:
    return random_scenario(seed)


def _within(value: float, bounds: tuple[float, float], slack: float = 1e-9) -> bool:
    return bounds[0] - slack <= value <= bounds[1] + slack


def test_the_same_seed_draws_the_same_scenario() -> None:
    for seed in (0, 7, 1000):
        assert random_scenario(seed) == random_scenario(seed)
        a, b = make_world(random_scenario(seed), seed), make_world(random_scenario(seed), seed)
        np.testing.assert_array_equal(a.odometry_errors, b.odometry_errors)
        np.testing.assert_array_equal(np.stack(a.T_base_lidar_initial), b.T_base_lidar_initial)
    assert random_scenario(1) != random_scenario(2)


def test_every_class_and_clock_is_reachable() -> None:
    assert {_spec(seed).scenario_class for seed in SEEDS} == set(scenario_classes())
    assert len(scenario_classes()) == 4 * 3 * 2
    assert {clock_kind(_spec(seed)) for seed in SEEDS} == set(CLOCKS)
    models = {
        (type(m.model).__name__, getattr(m.model, "beams", 0), getattr(m.model, "beam_field", "-"))
        for seed in SEEDS
        for m in _spec(seed).lidars
    }
    for beams in (16, 32, 64):
        for field in ("ring", "channel", "laser_id", None):
            assert ("SpinningLidar", beams, field) in models
    assert {name for name, _, _ in models} == {"Mid70", "Mid360", "SpinningLidar"}


def test_the_class_says_what_was_drawn() -> None:
    for seed in SEEDS:
        spec = _spec(seed)
        routine, sensors, errors = spec.scenario_class.split("/")
        families = {
            "rosette" if isinstance(m.model, Mid70 | Mid360) else "spinning" for m in spec.lidars
        }
        assert families == ({"rosette", "spinning"} if sensors == "mixed" else {sensors})
        bound = RANGES.extrinsic_small if errors == "small" else RANGES.extrinsic_large
        assert spec.extrinsic_error == bound
        assert spec.world is WorldKind.OPEN_FLOOR
        stops, turn = spec.motion.stops, np.degrees(spec.motion.heading(np.array([1e6]))[0][0])
        if routine == "rotate":
            assert _within(stops, RANGES.rotate_stops)
        elif routine == "figure-eight":
            assert abs(((turn + 180.0) % 360.0) - 180.0) < 1e-6, "it ends facing its start"
        final = spec.motion.poses(spec.motion.stop_intervals()[-1:, 0])[0, :2, 3]
        if routine != "rotate":
            np.testing.assert_allclose(final, [0.0, 0.0], atol=1e-9)  # back where it started


def test_routines_stay_inside_their_ranges() -> None:
    for seed in SEEDS:
        motion = _spec(seed).motion
        assert isinstance(motion, RouteMotion)
        routine = _spec(seed).scenario_class.split("/")[0]
        assert all(_within(d, RANGES.dwell_s) for d in motion.dwell_s)
        t = np.linspace(0, motion.duration_s, 4000)
        linear, angular = motion.twist(t)
        assert np.abs(linear[:, 0]).max() <= RANGES.drive_mps[1] + 1e-9
        assert np.degrees(np.abs(angular[:, 2])).max() <= RANGES.turn_dps[1] + 1e-9
        segments = [s for leg in motion.legs for s in leg]
        peak_turn = max(abs(s.angle_deg) / s.duration_s for s in segments if isinstance(s, Arc))
        assert _within(1.875 * peak_turn, (0, RANGES.turn_dps[1]))
        stops = motion.poses(motion.stop_intervals()[:, 0])
        steps = np.linalg.norm(np.diff(stops[:, :2, 3], axis=0), axis=1)
        if routine == "rotate":
            yaw = np.degrees(np.arctan2(stops[:, 1, 0], stops[:, 0, 0]))
            step = abs(((yaw[1] - yaw[0]) + 180.0) % 360.0 - 180.0)
            assert _within(step, RANGES.rotate_step_deg) and steps.max() < 1e-9
        elif routine in ("loop", "lane"):
            assert steps.max() <= RANGES.stop_spacing_m[1] + 1e-9
            extent = np.ptp(stops[:, :2, 3], axis=0)
            limit = RANGES.loop_side_m if routine == "loop" else RANGES.lane_length_m
            assert _within(extent.max(), limit)
        else:
            radius = np.ptp(motion.path_xy()[:, 1]) / 4.0
            assert _within(radius, RANGES.figure_eight_radius_m)
            assert steps.max() <= RANGES.stop_spacing_m[1] + 1e-9


def test_lidars_stay_inside_their_ranges() -> None:
    for seed in SEEDS:
        lidars = _spec(seed).lidars
        assert _within(len(lidars), RANGES.lidar_count)
        yaws = []
        for mount in lidars:
            roll, tilt, yaw = mount.rpy_deg
            roll -= 180.0 if isinstance(mount.model, Mid360) else 0.0
            assert _within(roll, RANGES.mount_roll_deg) and _within(tilt, RANGES.mount_tilt_deg)
            assert _within(mount.xyz[2], RANGES.mount_height_m)
            assert abs(mount.xyz[0]) <= 0.35 + 1e-9 and abs(mount.xyz[1]) <= 0.25 + 1e-9
            if isinstance(mount.model, SpinningLidar):
                low, high = mount.model.azimuth_mask_deg
                assert _within(high - low, RANGES.spinning_azimuth_deg) and low == -high
            yaws.append(yaw)
        gaps = [abs((a - b + 180) % 360 - 180) for i, a in enumerate(yaws) for b in yaws[i + 1 :]]
        assert min(gaps) >= RANGES.min_yaw_separation_deg


def test_objects_stand_near_the_path_clear_of_the_robot_and_each_other() -> None:
    for seed in SEEDS[:80]:
        spec = _spec(seed)
        objects = make_world(spec, seed).scene.objects
        assert _within(len(objects), RANGES.object_count)
        path = spec.motion.path_xy(step_m=0.02)
        robot = 0.5 * math.hypot(*spec.scene.robot_size_m[:2])
        for k, obj in enumerate(objects):
            centre = obj.T_world_object[:2, 3]
            nearest = np.linalg.norm(path - centre, axis=1).min()
            assert _within(nearest, RANGES.object_distance_m, slack=0.02)
            assert nearest >= robot + RANGES.robot_clearance_m + obj.radius_xy - 0.02
            height = 2 * obj.T_world_object[2, 3]
            assert _within(height, RANGES.object_height_m)
            for other in objects[k + 1 :]:
                gap = np.linalg.norm(centre - other.T_world_object[:2, 3])
                assert gap >= obj.radius_xy + other.radius_xy + RANGES.object_gap_m - 1e-9


def test_errors_and_clocks_stay_inside_their_ranges() -> None:
    for seed in SEEDS[:60]:
        spec = _spec(seed)
        assert _within(spec.odometry_error.translation_m, RANGES.odometry_translation_m)
        assert _within(spec.odometry_error.rotation_deg, RANGES.odometry_rotation_deg)
        assert _within(spec.odometry_drift.translation_m, RANGES.drift_translation_m)
        assert _within(spec.odometry_drift.rotation_deg, RANGES.drift_rotation_deg)
        world = make_world(spec, seed)
        for true, initial in zip(world.T_base_lidar_true, world.T_base_lidar_initial, strict=True):
            translation, rotation = pose_difference(true, initial)
            assert translation <= spec.extrinsic_error.translation_m + 1e-12
            assert rotation <= spec.extrinsic_error.rotation_deg + 1e-9
        offsets = spec.header_clock_offset_ns
        if clock_kind(spec) == "simulated":
            assert set(offsets) == {m.topic for m in spec.lidars} | {"/odom"}
            assert _within((spec.start_time_ns + offsets["/odom"]) / 1e9, RANGES.simulated_start_s)
        for offset in offsets.values() if clock_kind(spec) == "lidar-offset" else ():
            assert _within(offset / 86_400e9, RANGES.lidar_clock_offset_days)


def test_odometry_drift_grows_with_the_distance_travelled() -> None:
    spec = next(_spec(s) for s in SEEDS if _spec(s).scenario_class.startswith("lane"))
    spec = spec.model_copy(
        update={
            "odometry_error": spec.odometry_error.model_copy(
                update={"translation_m": 0.0, "rotation_deg": 0.0}
            ),
            "odometry_drift": spec.odometry_drift.model_copy(
                update={"translation_m": 0.15, "rotation_deg": 2.0}
            ),
        }
    )
    truth = make_world(spec, 5).truth()
    sizes = np.array(
        [pose_difference(s.T_odom_base_true, s.T_odom_base_initial) for s in truth.stops]
    )
    assert sizes[0, 0] == 0 and np.all(np.diff(sizes[:, 0]) >= -1e-12)
    np.testing.assert_allclose(sizes[-1], [0.15, 2.0], atol=1e-9)


def test_the_docstring_table_states_every_range() -> None:
    doc = module.__doc__ or ""
    for name, value in RANGES:
        if isinstance(value, tuple) and name != "mount_yaw_deg":
            low, high = value
            assert (
                f"{low:g}-{high:g}" in doc
                or f"{low:g}..{high:+g}" in doc
                or (f"{low:g}..{high:g}" in doc)
            ), name


def test_a_negative_seed_is_refused() -> None:
    with pytest.raises(ConfigError, match="seed must be 0 or more"):
        random_scenario(-1)
