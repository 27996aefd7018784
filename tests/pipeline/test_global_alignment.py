import numpy as np
import pytest

from pipeline.geometry import Plane
from pipeline.global_alignment import GlobalAlignmentConfig, align_globally
from pipeline.transforms import Points, apply, from_xyz_rpy, invert, pose_difference

CONFIG = GlobalAlignmentConfig()


def _scene(rng: np.random.Generator) -> Points:
    """Points on the sides of eight boxes of different sizes standing 1-3.5 m around the
    origin (G), the floor at z = -0.5 (G is a LiDAR's frame, 0.5 m up)."""
    boxes = []
    for k in range(8):
        angle = 2 * np.pi * k / 8 + rng.uniform(-0.2, 0.2)
        centre = rng.uniform(1.0, 3.5) * np.array([np.cos(angle), np.sin(angle)])
        half = rng.uniform(0.1, 0.3, size=2)
        side = rng.integers(0, 4, size=400)
        along = rng.uniform(-1, 1, size=400)
        x = np.where(side < 2, np.where(side == 0, -1, 1) * half[0], along * half[0])
        y = np.where(side >= 2, np.where(side == 2, -1, 1) * half[1], along * half[1])
        z = rng.uniform(-0.5, 0.3, size=400)
        boxes.append(np.stack([centre[0] + x, centre[1] + y, z], axis=1))
    return np.concatenate(boxes)


def _problem(
    start_error: np.ndarray,
) -> tuple[list[list[Points]], np.ndarray, np.ndarray, np.ndarray]:
    """Object clouds of a reference and one other LiDAR (facing back, 0.4 m behind it) at six
    stops turning in place and moving; the true and a start `T_ref_lidar` planar-off by
    `start_error` (x, y m; yaw deg)."""
    rng = np.random.default_rng(3)
    scene = _scene(rng)
    T_G_ref = np.stack([from_xyz_rpy([0.2 * j, 0.1 * j, 0.0], [0, 0, 35.0 * j]) for j in range(6)])
    T_true = np.stack([np.eye(4), from_xyz_rpy([-0.4, 0.1, 0.0], [0, 0, 180.0])])
    objects: list[list[Points]] = [[], []]
    for lidar in range(2):
        for T in T_G_ref:
            seen = scene[rng.random(len(scene)) < 0.5]
            objects[lidar].append(apply(invert(T @ T_true[lidar]), seen))
    start = T_true.copy()
    start[1] = from_xyz_rpy([start_error[0], start_error[1], 0], [0, 0, start_error[2]]) @ start[1]
    return objects, T_G_ref, T_true, start


FLOOR_G = Plane(normal=np.array([0.0, 0.0, 1.0]), offset=0.5)


def test_a_lidar_far_off_is_brought_near_its_true_pose() -> None:
    objects, T_G_ref, T_true, start = _problem(np.array([0.6, -0.45, 12.0]))
    result = align_globally(objects, T_G_ref, start, FLOOR_G, CONFIG)
    before = pose_difference(start[1], T_true[1])
    after = pose_difference(result.T_ref_lidar[1], T_true[1])
    assert before[0] > 0.7 and before[1] > 11
    assert result.moves[0].adopted
    assert after[0] < 0.06 and after[1] < 1.5
    np.testing.assert_allclose(result.T_G_ref, T_G_ref)  # the stops stay


def test_a_lidar_at_its_true_pose_stays_there() -> None:
    objects, T_G_ref, T_true, start = _problem(np.zeros(3))
    result = align_globally(objects, T_G_ref, start, FLOOR_G, CONFIG)
    assert not result.moves[0].adopted
    np.testing.assert_allclose(result.T_ref_lidar, T_true)


def test_a_lidar_without_objects_is_left_alone() -> None:
    objects, T_G_ref, _, start = _problem(np.array([0.6, -0.45, 12.0]))
    objects[1] = [np.zeros((0, 3)) for _ in objects[1]]
    result = align_globally(objects, T_G_ref, start, FLOOR_G, CONFIG)
    assert not result.moves[0].adopted
    np.testing.assert_allclose(result.T_ref_lidar, start)


@pytest.mark.parametrize("rotation_deg", [-25.0, 25.0])
def test_the_rotation_found_is_about_the_floor_normal_and_keeps_the_floor(
    rotation_deg: float,
) -> None:
    objects, T_G_ref, T_true, start = _problem(np.array([0.3, 0.2, rotation_deg]))
    result = align_globally(objects, T_G_ref, start, FLOOR_G, CONFIG)
    T = result.T_ref_lidar[1]
    # The LiDAR's up (z) stays the floor's normal, its height stays.
    np.testing.assert_allclose(T[:3, 2], [0, 0, 1], atol=1e-9)
    assert T[2, 3] == pytest.approx(T_true[1][2, 3])
    assert pose_difference(T, T_true[1])[1] < 2.5  # 10 cm cells seen 3 m away: ~2 deg
