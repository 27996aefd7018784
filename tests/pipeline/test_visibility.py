import math

import numpy as np
import pytest

from pipeline.visibility import ReferenceRays, VisibilityConfig, seen_by_reference, seen_metric


def _wall_cloud(x: float = 2.0) -> np.ndarray:
    """The reference's rays to a wall at `x` (m) ahead of it, a 1 m square, 1 cm apart."""
    y, z = np.meshgrid(np.arange(-0.5, 0.5, 0.01), np.arange(-0.5, 0.5, 0.01))
    return np.column_stack([np.full(y.size, x), y.ravel(), z.ravel()])


def _moved(T_G_lidar: np.ndarray, points: np.ndarray) -> np.ndarray:
    moved: np.ndarray = points @ T_G_lidar[:3, :3].T + T_G_lidar[:3, 3]
    return moved


def _yaw(deg: float, at: tuple[float, float, float]) -> np.ndarray:
    T = np.eye(4)
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = at
    return T


def test_points_on_surfaces_or_in_free_space_the_reference_saw_count_hidden_ones_do_not() -> None:
    config = VisibilityConfig()
    T_G_lidar = _yaw(90.0, (1.0, 0.0, 0.0))  # looking along +y of G from (1, 0, 0)
    rays = [ReferenceRays.of(_wall_cloud(), config)]
    in_lidar = np.array(
        [
            [2.0, 0.1, 0.0],  # on the wall it saw
            [2.03, -0.2, 0.1],  # 3 cm behind it: range noise, within the margin
            [1.2, 0.0, 0.2],  # in the free space its rays crossed
            [2.3, 0.0, 0.0],  # the wall's far face: hidden
            [2.0, 3.0, 0.0],  # beside the wall, where it returned nothing
            [-2.0, 0.0, 0.0],  # behind the LiDAR
        ]
    )
    seen = seen_by_reference(_moved(T_G_lidar, in_lidar), rays, T_G_lidar[None], config)
    assert seen.tolist() == [True, True, True, False, False, False]


def test_a_point_counts_when_any_stop_saw_it() -> None:
    config = VisibilityConfig()
    first, second = _yaw(0.0, (0.0, 0.0, 0.0)), _yaw(180.0, (4.5, 0.0, 0.0))
    # the same wall at x = 2 of G, seen from both sides: its far face from the second stop
    rays = [ReferenceRays.of(_wall_cloud(2.0), config), ReferenceRays.of(_wall_cloud(2.2), config)]
    far_face = np.array([[2.3, 0.0, 0.0]])
    both = np.stack([first, second])
    assert seen_by_reference(far_face, rays, both, config).tolist() == [True]
    assert seen_by_reference(far_face, rays[:1], both[:1], config).tolist() == [False]


def test_the_seen_metric_averages_the_seen_points_distances_to_the_references_surface() -> None:
    config = VisibilityConfig()
    wall = _wall_cloud()
    wall_normals = np.tile([-1.0, 0.0, 0.0], (len(wall), 1))
    seen_points = np.array([[2.004, 0.003, 0.0], [1.5, 0.0, 0.0]])  # 4 mm off; 0.5 m: capped
    hidden = np.array([[2.4, 0.0, 0.0], [2.4, 0.1, 0.0]])
    objects = [[wall], [np.vstack([seen_points, hidden])], [hidden]]
    T_ref_lidar = np.stack([np.eye(4)] * 3)
    metric = seen_metric(objects, [wall_normals], np.eye(4)[None], T_ref_lidar, config, 0.1)
    assert math.isnan(metric.per_lidar[0]) and math.isnan(metric.per_lidar[2])
    assert metric.per_lidar[1] == pytest.approx(np.mean([0.004, 0.1]))
    assert metric.seen == (0, 2, 0)
    assert metric.points == (len(wall), 4, 2)


def test_the_seen_metric_follows_the_poses_it_is_given() -> None:
    config = VisibilityConfig()
    wall = _wall_cloud()
    normals = np.tile([1.0, 0.0, 0.0], (len(wall), 1))
    on_the_wall = _wall_cloud()[::50]
    T_ref_lidar = np.stack([np.eye(4), _yaw(0.0, (0.01, 0.0, 0.0))])  # the other 1 cm ahead
    metric = seen_metric(
        [[wall], [on_the_wall]], [normals], np.eye(4)[None], T_ref_lidar, config, 0.1
    )
    assert metric.per_lidar[1] == pytest.approx(0.01)


def test_a_stop_without_returns_sees_nothing() -> None:
    config = VisibilityConfig()
    rays = [ReferenceRays.of(np.zeros((0, 3)), config)]
    seen = seen_by_reference(np.array([[1.0, 0.0, 0.0]]), rays, np.eye(4)[None], config)
    assert seen.tolist() == [False]


def test_a_point_whose_reference_normal_is_undefined_counts_at_the_cap() -> None:
    wall = _wall_cloud()
    normals = np.full((len(wall), 3), np.nan)
    T_ref_lidar = np.stack([np.eye(4)] * 2)
    metric = seen_metric(
        [[wall], [wall[::50]]], [normals], np.eye(4)[None], T_ref_lidar, VisibilityConfig(), 0.1
    )
    assert metric.per_lidar[1] == 0.1
