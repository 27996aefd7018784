"""Trajectory samples: ordering, duplicates, invalid quaternions, mean pose."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.io.trajectory import Trajectory, valid_samples
from pipeline.transforms import pose_difference


def test_samples_are_sorted_and_the_last_of_a_stamp_wins() -> None:
    stamps = np.array([30, 10, 20, 10])
    translations = np.array([[3.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0], [1.5, 0, 0]])
    quats = np.tile([0.0, 0.0, 0.0, 2.0], (4, 1))  # not unit: normalised on the way in

    trajectory = Trajectory.from_arrays(stamps, translations, quats, "test")

    np.testing.assert_array_equal(trajectory.stamps_ns, [10, 20, 30])
    np.testing.assert_array_equal(trajectory.translations[:, 0], [1.5, 2.0, 3.0])
    np.testing.assert_allclose(trajectory.rotations_xyzw, np.tile([0, 0, 0, 1.0], (3, 1)))


def test_invalid_samples_are_masked() -> None:
    translations = np.array([[0.0, 0, 0], [np.nan, 0, 0], [0.0, 0, 0], [0.0, 0, 0]])
    quats = np.array([[0, 0, 0, 1.0], [0, 0, 0, 1.0], [0, 0, 0, 0.0], [np.inf, 0, 0, 1.0]])
    np.testing.assert_array_equal(valid_samples(translations, quats), [True, False, False, False])


def test_mean_pose_of_a_span() -> None:
    angles = np.array([[9.0], [10.0], [11.0], [50.0]])
    quats = Rotation.from_euler("z", angles, degrees=True).as_quat()
    translations = np.array([[1.0, 0, 0], [2.0, 0, 0], [3.0, 0, 0], [9.0, 0, 0]])
    trajectory = Trajectory.from_arrays(np.arange(4), translations, quats, "test")

    T = trajectory.mean_pose(0, 2)

    expected = np.eye(4)
    expected[:3, :3] = Rotation.from_euler("z", 10.0, degrees=True).as_matrix()
    expected[0, 3] = 2.0
    distance, angle = pose_difference(T, expected)
    assert distance < 1e-12 and angle < 1e-4
