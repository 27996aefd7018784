import numpy as np
import pytest

from pipeline.downsample import voxel_downsample
from pipeline.errors import BadInputError


def test_each_occupied_voxel_becomes_the_centroid_of_its_points() -> None:
    points = np.array([[0.01, 0.01, 0.01], [0.03, 0.03, 0.03], [0.51, 0.0, 0.0], [0.55, 0.04, 0.0]])
    result = voxel_downsample(points, 0.1)
    expected = np.array([[0.02, 0.02, 0.02], [0.53, 0.02, 0.0]])
    assert len(result) == 2
    order = np.argsort(result[:, 0])
    np.testing.assert_allclose(result[order], expected, atol=1e-12)


def test_negative_coordinates_share_no_voxel_with_positive_ones() -> None:
    points = np.array([[-0.01, 0.0, 0.0], [0.01, 0.0, 0.0]])
    assert len(voxel_downsample(points, 0.1)) == 2


def test_zero_voxel_size_keeps_every_point() -> None:
    points = np.random.default_rng(0).normal(size=(50, 3))
    np.testing.assert_array_equal(voxel_downsample(points, 0.0), points)


def test_points_beyond_the_grid_are_refused() -> None:
    with pytest.raises(BadInputError, match="do not fit the voxel grid"):
        voxel_downsample(np.array([[1e6, 0.0, 0.0]]), 0.02)
