"""Simulated problems: true geometry recovered with true poses, labels aligned, reproducible."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.problem import CalibrationProblem, ScanPattern
from pipeline.synth import Truth, get_scenario, make_world, scan, simulate_problem
from pipeline.synth.motion import ArcMotion
from pipeline.synth.scene import SceneObject
from pipeline.transforms import apply, pose_difference


def _world_points(
    problem: CalibrationProblem, truth: Truth, j: int, frame: str, true: bool
) -> np.ndarray:
    stop, stop_truth, lidar = problem.stops[j], truth.stops[j], truth.lidar(frame)
    if true:
        T = stop_truth.T_odom_base_true @ lidar.T_base_lidar_true
    else:
        T = stop.T_odom_base @ problem.lidar(frame).T_base_lidar
    return apply(T, stop.clouds[frame])


def test_same_seed_same_problem(tiny_problem: tuple[CalibrationProblem, Truth]) -> None:
    problem, truth = tiny_problem
    again, truth_again = simulate_problem("tiny", seed=7)
    for stop, other in zip(problem.stops, again.stops, strict=True):
        for frame in problem.frames:
            np.testing.assert_array_equal(stop.clouds[frame], other.clouds[frame])
    assert truth.to_json() == truth_again.to_json()
    different, _ = simulate_problem("tiny", seed=8)
    assert not np.array_equal(
        different.stops[0].clouds["lidar_front"][:50], problem.stops[0].clouds["lidar_front"][:50]
    )


def test_problem_layout(tiny_problem: tuple[CalibrationProblem, Truth]) -> None:
    problem, truth = tiny_problem
    assert problem.frames == ("lidar_front", "lidar_rear")
    assert truth.reference_frame == "lidar_front"
    assert len(problem.stops) == len(truth.stops) == 4
    for j, stop in enumerate(problem.stops):
        assert stop.t_start == truth.stops[j].t_start and stop.duration == pytest.approx(1.3)
        np.testing.assert_array_equal(stop.T_odom_base, truth.stops[j].T_odom_base_initial)
        for frame, cloud in stop.clouds.items():
            assert cloud.dtype == np.float64 and cloud.shape[1] == 3
            assert len(cloud) > 1000
            assert stop.scan_counts[frame] == 13
            assert len(truth.stop_labels(j, frame)) == len(cloud)
    for lidar in problem.lidars:
        np.testing.assert_array_equal(
            lidar.T_base_lidar, truth.lidar(lidar.frame).T_base_lidar_initial
        )
        assert lidar.points_per_second == pytest.approx(5000.0)


def test_floor_points_lie_at_z0_with_true_poses_only(
    tiny_problem: tuple[CalibrationProblem, Truth],
) -> None:
    problem, truth = tiny_problem
    for j in range(len(problem.stops)):
        for frame in problem.frames:
            labels = truth.stop_labels(j, frame)
            floor = (labels.object_index < 0) & ~labels.is_bleeding
            z = _world_points(problem, truth, j, frame, true=True)[floor, 2]
            assert abs(z.mean()) < 0.003 and z.std() < 0.02
            z_initial = _world_points(problem, truth, j, frame, true=False)[floor, 2]
            assert abs(z_initial.mean()) > 0.003 or z_initial.std() > 0.02


def test_object_points_lie_on_their_object(tiny_problem: tuple[CalibrationProblem, Truth]) -> None:
    problem, truth = tiny_problem
    for j in range(len(problem.stops)):
        for frame in problem.frames:
            labels = truth.stop_labels(j, frame)
            points = _world_points(problem, truth, j, frame, true=True)
            on_object = (labels.object_index >= 0) & ~labels.is_bleeding
            assert on_object.sum() > 20
            for k in np.unique(labels.object_index[on_object]):
                obj: SceneObject = truth.objects[k]
                distance = obj.distance(points[on_object & (labels.object_index == k)])
                assert np.quantile(distance, 0.99) < 0.06


def test_bleeding_points_float_near_object_edges(
    tiny_problem: tuple[CalibrationProblem, Truth],
) -> None:
    problem, truth = tiny_problem
    total = bleeding = 0
    for j in range(len(problem.stops)):
        for frame in problem.frames:
            labels = truth.stop_labels(j, frame)
            points = _world_points(problem, truth, j, frame, true=True)[labels.is_bleeding]
            total += len(labels)
            bleeding += len(points)
            if len(points) == 0:
                continue
            to_object = np.min([obj.distance(points) for obj in truth.objects], axis=0)
            assert np.all(to_object < 1.0), (
                "bleeding points sit between an object and its background"
            )
            assert np.median(np.minimum(to_object, np.abs(points[:, 2]))) > 0.03
    assert 0.001 < bleeding / total < 0.05


def test_perturbations_within_the_stated_bounds() -> None:
    for seed in range(4):
        world = make_world("set2-box", seed)
        truth = world.truth()
        for lidar in truth.lidars:
            translation, rotation = pose_difference(
                lidar.T_base_lidar_true, lidar.T_base_lidar_initial
            )
            assert translation <= 0.2 + 1e-12 and rotation <= 5.0 + 1e-9
            assert translation > 0 and rotation > 0
        for stop in truth.stops:
            translation, rotation = pose_difference(stop.T_odom_base_true, stop.T_odom_base_initial)
            assert translation <= 0.2 + 1e-12 and rotation <= 3.0 + 1e-9


def test_every_lidar_sees_objects_at_most_stops() -> None:
    spec = get_scenario("set1-cylinder")
    spec = spec.model_copy(update={"motion": spec.motion.model_copy(update={"dwell_s": 0.3})})
    problem, truth = simulate_problem(spec, seed=3, rate_scale=0.05)
    for frame in problem.frames:
        seen = [
            (truth.stop_labels(j, frame).object_index >= 0).sum() > 30
            for j in range(len(problem.stops))
        ]
        assert sum(seen) >= 0.75 * len(seen), (frame, seen)


def test_moving_scan_points_are_in_the_sensor_frame_at_their_firing_time() -> None:
    world = make_world("driven", seed=2, rate_scale=0.2)
    lidar = 0
    period = world.scan_period_ns(lidar)
    motion = world.spec.motion
    assert isinstance(motion, ArcMotion)
    # The scan in the middle of the first move, where the robot is fastest.
    moving = round((motion.dwell_s + motion.move_s / 2) * 1e9 / period)
    assert not world.is_still(lidar, moving)
    labelled = world.simulate_scan(lidar, moving)
    mount = world.spec.lidars[lidar]
    poses = world.spec.motion.poses(labelled.times) @ mount.T_base_lidar()
    world_points = np.einsum("nij,nj->ni", poses[:, :3, :3], labelled.points) + poses[:, :3, 3]
    floor = (labelled.object_index < 0) & ~labelled.is_bleeding
    # Each 10 ms slice is cast from its middle pose: residual motion within a slice is small.
    assert np.abs(world_points[floor, 2]).mean() < 0.03
    assert labelled.stamp_ns == world.spec.start_time_ns + moving * period
    # Floor heights cannot show a planar motion; object points can: placed with the pose at
    # their own time they lie on their object, placed with the scan's first pose they do not.
    start = world.spec.motion.poses(labelled.times[:1])[0] @ mount.T_base_lidar()
    on_object = np.flatnonzero((labelled.object_index >= 0) & ~labelled.is_bleeding)
    assert len(on_object) > 20
    static_points = apply(start, labelled.points[on_object])
    moving_distance, static_distance = np.zeros(len(on_object)), np.zeros(len(on_object))
    for k in np.unique(labelled.object_index[on_object]):
        mine = labelled.object_index[on_object] == k
        moving_distance[mine] = world.scene.objects[k].distance(world_points[on_object][mine])
        static_distance[mine] = world.scene.objects[k].distance(static_points[mine])
    assert np.median(moving_distance) < 0.02
    assert np.median(static_distance) > 2 * np.median(moving_distance)


def test_scan_with_a_constant_pose_function_equals_a_fixed_pose() -> None:
    world = make_world("tiny", seed=1)
    model = world.spec.lidars[0].model
    T = world.spec.motion.poses(np.zeros(1))[0] @ world.T_base_lidar_true[0]
    fixed = scan(world.scene, model, T, 0.0, 0.1, np.random.default_rng(5), rate_scale=0.2)
    moving = scan(
        world.scene,
        model,
        lambda t: np.broadcast_to(T, (len(t), 4, 4)),
        0.0,
        0.1,
        np.random.default_rng(5),
        rate_scale=0.2,
    )
    np.testing.assert_allclose(fixed.points, moving.points, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(fixed.is_bleeding, moving.is_bleeding)
    assert len(fixed) > 500


def test_spinning_lidars_see_the_floor_and_objects() -> None:
    spec = get_scenario("spinning")
    spec = spec.model_copy(update={"motion": ArcMotion(stops=2, dwell_s=0.3, move_s=0.2)})
    problem, truth = simulate_problem(spec, seed=0, rate_scale=0.1)
    for frame in problem.frames:
        labels = truth.stop_labels(0, frame)
        assert len(labels) > 1000 and (labels.object_index >= 0).any()
    axis = truth.lidar("lidar_front").optical_axis
    np.testing.assert_allclose(axis, [1.0, 0.0, 0.0], atol=1e-12)
    assert {lidar.scan_pattern for lidar in problem.lidars} == {ScanPattern.REPETITIVE}
