import numpy as np

from pipeline.calibrate import calibrate
from pipeline.config import PipelineConfig
from pipeline.observability import ObservabilityConfig, level_rotation
from tests.pipeline.calibration_data import box_calibration, box_problem, floor_only_calibration


def test_level_rotation_turns_the_floor_normal_to_z_by_the_shortest_way() -> None:
    up = np.array([0.1, -0.05, 1.0])
    R = level_rotation(up)
    np.testing.assert_allclose(R @ (up / np.linalg.norm(up)), [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    # No turn about z: the horizontal axis orthogonal to the tilt stays put.
    axis = np.cross(up, [0.0, 0.0, 1.0])
    np.testing.assert_allclose(R @ axis, axis, atol=1e-12)


def test_objects_determine_every_degree_of_freedom() -> None:
    result = box_calibration()
    for lidar in result.lidars[1:]:
        assert lidar.uncertainty.undetermined == ()
        assert max(lidar.uncertainty.stddev_translation_m) < 0.005
        assert max(lidar.uncertainty.stddev_rotation_deg) < 0.1


def test_a_bare_floor_leaves_x_y_and_yaw_undetermined_and_only_those() -> None:
    result = floor_only_calibration()
    reference, other = result.lidars
    assert reference.uncertainty.undetermined == ()
    assert other.uncertainty.undetermined == ("x", "y", "yaw")
    # The floor still fixes height, roll and pitch.
    assert other.uncertainty.stddev_translation_m[2] < 0.01
    assert max(other.uncertainty.stddev_rotation_deg[:2]) < 0.1


def test_reported_stddev_are_the_formal_ones_scaled_and_the_undetermined_judged_before() -> None:
    problem, _ = box_problem()
    formal = ObservabilityConfig(stddev_scale_translation=1.0, stddev_scale_rotation=1.0)
    scaled = ObservabilityConfig(stddev_scale_translation=7.0, stddev_scale_rotation=3.0)
    results = [
        calibrate(problem, PipelineConfig(observability=config)) for config in (formal, scaled)
    ]
    for plain, wide in zip(results[0].lidars, results[1].lidars, strict=True):
        np.testing.assert_allclose(
            wide.uncertainty.stddev_translation_m, 7.0 * plain.uncertainty.stddev_translation_m
        )
        np.testing.assert_allclose(
            wide.uncertainty.stddev_rotation_deg, 3.0 * plain.uncertainty.stddev_rotation_deg
        )
        assert wide.uncertainty.undetermined == plain.uncertainty.undetermined
