"""SE(3) helpers: round trips and the frame convention."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.transforms import (
    apply,
    exp_se3,
    from_translation_xyzw,
    from_xyz_rpy,
    invert,
    log_se3,
    pose_difference,
    rotation_angle_deg,
    to_translation_xyzw,
)


def random_transform(rng: np.random.Generator) -> np.ndarray:
    return from_translation_xyzw(rng.normal(size=3), Rotation.random(random_state=rng).as_quat())


def test_translation_xyzw_round_trip() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        T = random_transform(rng)
        translation, quat = to_translation_xyzw(T)
        assert quat[3] >= 0
        np.testing.assert_allclose(from_translation_xyzw(translation, quat), T, atol=1e-12)


def test_parent_child_convention_maps_child_points_into_parent() -> None:
    # base_link -> lidar: lidar 1 m ahead of the base, yawed 90 deg left.
    T_base_lidar = from_xyz_rpy([1.0, 0.0, 0.0], [0.0, 0.0, np.pi / 2])
    point_in_lidar = np.array([[1.0, 0.0, 0.0]])  # 1 m along the lidar's x axis
    np.testing.assert_allclose(apply(T_base_lidar, point_in_lidar), [[1.0, 1.0, 0.0]], atol=1e-12)


def test_invert_and_compose() -> None:
    rng = np.random.default_rng(1)
    T = random_transform(rng)
    np.testing.assert_allclose(T @ invert(T), np.eye(4), atol=1e-12)


def unit(v: np.ndarray) -> np.ndarray:
    return np.asarray(v / np.linalg.norm(v))


def test_exp_log_round_trip_including_small_angles() -> None:
    rng = np.random.default_rng(2)
    for scale in (1e-12, 1e-6, 0.1, 1.0, 2.5):
        xi = np.concatenate([rng.normal(size=3), unit(rng.normal(size=3)) * scale])
        np.testing.assert_allclose(log_se3(exp_se3(xi)), xi, atol=1e-9)


def test_pose_difference_and_angle() -> None:
    T_a = from_xyz_rpy([0, 0, 0], [0, 0, 0])
    T_b = from_xyz_rpy([0.3, 0.4, 0], [0, 0, np.radians(2.0)])
    distance, angle = pose_difference(T_a, T_b)
    assert distance == pytest.approx(0.5)
    assert angle == pytest.approx(2.0)
    assert rotation_angle_deg(np.eye(3)) == 0.0


def test_zero_quaternion_is_refused() -> None:
    with pytest.raises(ValueError, match="no direction"):
        from_translation_xyzw([0, 0, 0], [0, 0, 0, 0])
