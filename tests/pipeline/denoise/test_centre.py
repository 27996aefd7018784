"""The observation centre: where the optical axis meets the floor, else the point nearest it."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.denoise import fit_floor_plane, observation_centre
from pipeline.errors import BadInputError
from tests.pipeline.denoise.clouds import AXIS, AXIS_ON_FLOOR, FLOOR_PLANE, floor_in_lidar_frame


def test_the_centre_is_where_the_axis_meets_the_given_floor() -> None:
    cloud = floor_in_lidar_frame(5_000)
    np.testing.assert_allclose(observation_centre(cloud, AXIS, FLOOR_PLANE), AXIS_ON_FLOOR)


def test_the_centre_is_where_the_axis_meets_the_fitted_floor() -> None:
    cloud = floor_in_lidar_frame(20_000, noise=0.02)  # the synthesiser's Mid-70 range noise
    np.testing.assert_allclose(observation_centre(cloud, AXIS), AXIS_ON_FLOOR, atol=0.01)


def test_an_unnormalised_axis_gives_the_same_centre() -> None:
    cloud = floor_in_lidar_frame(5_000)
    np.testing.assert_allclose(observation_centre(cloud, (3.0, 0, 0), FLOOR_PLANE), AXIS_ON_FLOOR)


def test_the_floor_fit_prefers_the_floor_to_a_box_face() -> None:
    rng = np.random.default_rng(1)
    floor = floor_in_lidar_frame(20_000)
    box_face = np.column_stack(
        [np.full(3000, 1.0), rng.uniform(-0.2, 0.2, 3000), rng.uniform(-0.2, 0.2, 3000)]
    )

    plane = fit_floor_plane(np.vstack([floor, box_face]))

    assert plane is not None
    np.testing.assert_allclose(plane * np.sign(plane[3]), FLOOR_PLANE, atol=0.01)


@pytest.mark.parametrize(
    "axis",
    [
        (1.0, 0.0, 1.0),  # above the horizon: never meets the floor
        (0.0, 1.0, 0.0),  # parallel to the floor
    ],
)
def test_an_axis_that_misses_the_floor_takes_the_point_nearest_the_axis(
    axis: tuple[float, float, float],
) -> None:
    cloud = floor_in_lidar_frame(5_000)

    centre = observation_centre(cloud, axis, FLOOR_PLANE)

    unit = np.asarray(axis) / np.linalg.norm(axis)
    off_axis = np.linalg.norm(cloud - np.clip(cloud @ unit, 0, None)[:, None] * unit, axis=1)
    nearest = cloud[np.argmin(off_axis)]
    np.testing.assert_array_equal(centre, nearest)


def test_a_floor_met_beyond_the_farthest_point_counts_as_missed() -> None:
    cloud = floor_in_lidar_frame(5_000)
    cloud = cloud[np.linalg.norm(cloud, axis=1) < 0.8]  # the axis meets the floor at 0.87 m

    centre = observation_centre(cloud, AXIS, FLOOR_PLANE)

    assert np.any(np.all(cloud == centre, axis=1))


def test_a_cloud_at_one_spot_has_that_spot_as_its_centre() -> None:
    cloud = np.tile([[1.0, 0.2, -0.3]], (50, 1))
    assert fit_floor_plane(cloud) is None
    np.testing.assert_array_equal(observation_centre(cloud, AXIS), cloud[0])


def test_bad_axes_and_empty_clouds_are_refused() -> None:
    cloud = floor_in_lidar_frame(100)
    with pytest.raises(BadInputError, match="optical axis must be a non-zero"):
        observation_centre(cloud, (0.0, 0.0, 0.0))
    with pytest.raises(BadInputError, match="optical axis must be a non-zero"):
        observation_centre(cloud, (1.0, 0.0))
    with pytest.raises(BadInputError, match="empty cloud has no observation centre"):
        observation_centre(np.zeros((0, 3)), AXIS)
