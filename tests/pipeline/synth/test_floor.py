"""The uneven floor: rays hit it exactly and first, the robot rests on it, odometry stays planar."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from pipeline.synth import make_world
from pipeline.synth.floor import SINK_M, FloorSpec, FloorSurface, draw_floor
from pipeline.synth.objects import ObjectKind, SceneObject
from pipeline.transforms import apply, from_xyz_rpy, invert
from tests.pipeline.synth.worlds import short, small_problem


def _floor(seed: int = 3, steps: int = 2) -> FloorSurface:
    spec = FloorSpec(steps=steps, step_distance_m=(0.0, 1.0))
    return draw_floor(spec, np.random.default_rng(seed), 12.0)


def _rays(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    origins = np.column_stack(
        [rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(0.3, 1, n)]
    )
    directions = rng.normal(size=(n, 3))
    directions[:, 2] = -np.abs(directions[:, 2])
    return origins, directions / np.linalg.norm(directions, axis=1, keepdims=True)


def test_drawn_floor_is_within_the_spec() -> None:
    spec = FloorSpec()
    floor = draw_floor(spec, np.random.default_rng(1), 12.0)
    slope = math.degrees(math.atan(float(np.linalg.norm(floor.gradient))))
    assert spec.slope_deg[0] <= slope <= spec.slope_deg[1]
    assert np.all((floor.amplitude >= 0.003) & (floor.amplitude <= 0.005))
    lengths = 2 * math.pi / np.linalg.norm(floor.wave_vector, axis=1)
    assert np.all((lengths >= 1.0) & (lengths <= 3.0))
    assert len(floor.step_rise) == 1 and 0.002 <= floor.step_rise[0] <= 0.005
    # The joint is a step: the height jumps by its rise across the line.
    normal, offset = floor.step_normal[0], floor.step_offset[0]
    across = np.array([normal * (offset - 1e-7), normal * (offset + 1e-7)])
    assert np.diff(floor.height(across))[0] == pytest.approx(floor.step_rise[0], abs=1e-6)


def test_rays_hit_the_floor_on_it_and_first() -> None:
    floor = _floor()
    origins, directions = _rays(20_000)
    range_m, normal = floor.intersect(origins, directions, 40.0)
    hit = np.isfinite(range_m)
    assert hit.mean() > 0.9
    points = origins[hit] + directions[hit] * range_m[hit, None]
    gap = points[:, 2] - floor.height(points[:, :2])
    # On the surface, or on a joint's vertical face (then within its rise of the height).
    assert np.quantile(np.abs(gap), 0.99) < 1e-8
    assert np.abs(gap).max() <= floor.step_rise.max() + 1e-9
    # Nothing is hit earlier: every point of the ray before its hit lies above the floor.
    rows = np.flatnonzero(hit)[:3000]
    s = range_m[rows, None] * np.linspace(0.0, 0.9999, 300)[None]
    before = origins[rows, None] + directions[rows, None] * s[..., None]
    heights = floor.height(before[..., :2].reshape(-1, 2)).reshape(s.shape)
    assert (before[..., 2] > heights).all(axis=1).mean() > 0.999
    np.testing.assert_allclose(np.linalg.norm(normal[hit], axis=1), 1.0)
    assert np.all(normal[hit, 2] > 0.99)


def test_rays_past_the_floor_square_or_range_miss() -> None:
    floor = _floor()
    origins = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    directions = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, -0.01], [0.0, 0.0, -1.0]])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    range_m, _ = floor.intersect(origins, directions, 40.0)
    assert np.isinf(range_m[0]) and np.isinf(range_m[1])  # upwards; beyond the 12 m square
    assert range_m[2] == pytest.approx(1.0 - floor.height(np.zeros((1, 2)))[0], abs=1e-9)
    assert np.isinf(floor.intersect(origins[2:], directions[2:], 0.5)[0][0])


def test_a_robot_rests_on_the_floor_under_its_wheels() -> None:
    floor = _floor(steps=0)
    planar = np.stack([from_xyz_rpy([x, -0.5 * x, 0.3], [0.2, 0.1, x]) for x in (0.0, 1.3, 2.1)])
    rested = floor.rest(planar, (0.7, 0.5))
    wheels = np.array(
        [[0.35, 0.25, 0.0], [0.35, -0.25, 0.0], [-0.35, 0.25, 0.0], [-0.35, -0.25, 0.0]]
    )
    for T_world_base, T_planar in zip(rested, planar, strict=True):
        np.testing.assert_allclose(T_world_base[:2, 3], T_planar[:2, 3])
        np.testing.assert_allclose(
            T_world_base[:3, :3] @ T_world_base[:3, :3].T, np.eye(3), atol=1e-12
        )
        # Heading kept: the base's x axis points where the planar one does.
        heading = T_world_base[:2, 0] / np.linalg.norm(T_world_base[:2, 0])
        np.testing.assert_allclose(
            heading, T_planar[:2, 0] / np.linalg.norm(T_planar[:2, 0]), atol=1e-12
        )
        contact = apply(T_world_base, wheels)
        under = floor.height(contact[:, :2])
        # Four wheels on a wavy floor: the plane misses each by the floor's twist, a few mm.
        assert np.abs(contact[:, 2] - under).max() < 0.004
        # Least squares on a symmetric footprint: the base sits at the wheels' mean height.
        assert T_world_base[2, 3] == pytest.approx(under.mean(), abs=1e-6)
        assert T_world_base[2, 3] != 0.0


def test_objects_stand_on_the_floor() -> None:
    floor = _floor()
    box = SceneObject(
        ObjectKind.BOX,
        {"x": 0.3, "y": 0.3, "z": 0.25},
        from_xyz_rpy([1.0, 0.5, 0.125], [0, 0, 0.3]),
        0.5,
    )
    stood = floor.stand(box)
    ground = floor.height(np.array([[1.0, 0.5]]))[0]
    top = stood.T_world_object[2, 3] + 0.5 * stood.dimensions["z"]
    bottom = stood.T_world_object[2, 3] - 0.5 * stood.dimensions["z"]
    assert top == pytest.approx(ground + 0.25) and bottom == pytest.approx(ground - SINK_M)
    np.testing.assert_array_equal(stood.T_world_object[:2, 3], box.T_world_object[:2, 3])


def test_floor_round_trips_through_json() -> None:
    floor = _floor()
    again = FloorSurface.from_json(floor.to_json())
    xy = np.random.default_rng(0).uniform(-5, 5, size=(100, 2))
    np.testing.assert_array_equal(floor.height(xy), again.height(xy))


def test_a_floor_spec_out_of_order_is_refused() -> None:
    with pytest.raises(ValidationError, match="slope_deg must be"):
        FloorSpec(slope_deg=(0.5, 0.2))
    with pytest.raises(ValidationError, match="a ramp is not a floor"):
        FloorSpec(slope_deg=(1.0, 12.0))


def test_true_base_follows_the_floor_while_odometry_stays_planar() -> None:
    world = make_world(short("uneven-floor"), seed=2)
    floor = world.scene.floor
    assert floor is not None
    truth = world.truth()
    doc = truth.to_json()
    tilts = []
    for stop, entry in zip(truth.stops, doc["stops"], strict=True):
        T = stop.T_odom_base_true
        # Within the floor's relief of the height under the base's centre.
        assert T[2, 3] == pytest.approx(floor.height(T[None, :2, 3])[0], abs=floor.relief_m)
        assert entry["base_on_floor"]["height_m"] == pytest.approx(T[2, 3])
        tilts.append(
            math.hypot(entry["base_on_floor"]["roll_deg"], entry["base_on_floor"]["pitch_deg"])
        )
    assert min(tilts) > 0.1 and max(tilts) < 1.5
    t = world.stop_times[:, 0]
    # Odometry is the planar plan times its drift, blind to the floor's tilt and height.
    planar = world.spec.motion.poses(t)
    np.testing.assert_allclose(
        np.stack([invert(p) @ o for p, o in zip(planar, world.odometry(t), strict=True)]),
        world.odometry_errors,
        atol=1e-12,
    )


def test_floor_points_lie_on_the_floor_with_the_true_tilted_poses_only() -> None:
    spec = short("uneven-floor")
    problem, truth = small_problem("uneven-floor", seed=2, rate_scale=0.1)
    assert truth.floor is not None and problem.recording is not None
    planar = spec.motion.poses(
        np.array([stop.t_start - problem.recording.t_start for stop in problem.stops])
    )
    for j, stop in enumerate(problem.stops):
        for frame in problem.frames:
            labels = truth.stop_labels(j, frame)
            on_floor = (labels.object_index == -1) & ~labels.is_bleeding
            points = stop.clouds[frame][on_floor]
            T_base_lidar = truth.lidar(frame).T_base_lidar_true
            world = apply(truth.stops[j].T_odom_base_true @ T_base_lidar, points)
            residual = world[:, 2] - truth.floor.height(world[:, :2])
            assert abs(residual.mean()) < 0.002 and residual.std() < 0.03
            # The base's height, roll and pitch matter: the planar pose misplaces the floor.
            flat = apply(planar[j] @ T_base_lidar, points)
            off = flat[:, 2] - truth.floor.height(flat[:, :2])
            assert np.abs(off.mean()) > 2 * np.abs(residual.mean()) + 0.002
