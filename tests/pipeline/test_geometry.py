"""The shared geometry against independent references: scipy's matrix exponential of the twist
matrix, scipy's `RigidTransform`, `np.cross`, and the plane and grid definitions themselves."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from numpy.typing import NDArray
from scipy.linalg import expm
from scipy.spatial.transform import RigidTransform, Rotation

from pipeline.errors import BadInputError
from pipeline.geometry import (
    Plane,
    adjoint,
    exp_se3,
    hat,
    log_se3,
    pack_cells,
    plane_in_parent,
    tangent_basis,
    voxel_keys,
)
from pipeline.transforms import from_translation_xyzw, invert

vectors = arrays(np.float64, 3, elements=st.floats(-10.0, 10.0))
# Rotation angles below pi, where the rotation vector of a rotation is unique.
rotation_vectors = arrays(np.float64, 3, elements=st.floats(-1.8, 1.8))
seeds = st.integers(0, 2**32 - 1)


def twist_matrix(xi: NDArray[np.float64]) -> NDArray[np.float64]:
    """The (4, 4) element of se(3) whose matrix exponential is `exp_se3(xi)`."""
    X = np.zeros((4, 4))
    X[:3, :3] = hat(xi[3:])
    X[:3, 3] = xi[:3]
    return X


def random_transform(seed: int) -> NDArray[np.float64]:
    rng = np.random.default_rng(seed)
    return from_translation_xyzw(
        rng.normal(size=3) * 5, Rotation.random(random_state=rng).as_quat()
    )


@given(vectors, vectors)
def test_hat_is_the_cross_product(a: NDArray[np.float64], b: NDArray[np.float64]) -> None:
    np.testing.assert_allclose(hat(a) @ b, np.cross(a, b), atol=1e-12)
    np.testing.assert_array_equal(hat(a).T, -hat(a))


def test_hat_of_many_vectors_is_each_vectors_hat() -> None:
    v = np.random.default_rng(0).normal(size=(2, 5, 3))
    many = hat(v)
    assert many.shape == (2, 5, 3, 3)
    for index in np.ndindex(2, 5):
        np.testing.assert_array_equal(many[index], hat(v[index]))


@given(vectors, rotation_vectors.filter(lambda phi: np.linalg.norm(phi) > 1e-3))
def test_exp_is_the_matrix_exponential(rho: NDArray[np.float64], phi: NDArray[np.float64]) -> None:
    xi = np.concatenate([rho, phi])
    T = exp_se3(xi)
    np.testing.assert_allclose(T, expm(twist_matrix(xi)), atol=1e-12 * (1 + np.abs(rho).max()))
    # scipy orders its exponential coordinates rotation first.
    scipy_T = RigidTransform.from_exp_coords(np.concatenate([phi, rho])).as_matrix()
    np.testing.assert_allclose(T, scipy_T, atol=1e-12 * (1 + np.abs(rho).max()))


@given(vectors, rotation_vectors)
def test_log_inverts_exp(rho: NDArray[np.float64], phi: NDArray[np.float64]) -> None:
    xi = np.concatenate([rho, phi])
    np.testing.assert_allclose(log_se3(exp_se3(xi)), xi, atol=1e-9 * (1 + np.abs(rho).max()))


@pytest.mark.parametrize("angle", [0.0, 1e-12, 2e-9, 1e-8, 1e-6, 1e-4, 0.1, 3.0])
def test_exp_and_log_hold_at_small_and_large_angles(angle: float) -> None:
    rng = np.random.default_rng(2)
    axis, rho = rng.normal(size=3), rng.normal(size=3)
    xi = np.concatenate([rho / np.linalg.norm(rho), axis / np.linalg.norm(axis) * angle])
    T = exp_se3(xi)
    # Between the series' switch (1e-9 rad) and ~1e-7 rad, 1 - cos(theta) cancels and the
    # translation loses up to theta / 2 per metre of rho (5 nm at 1e-8 rad): measured, bounded
    # here, far below anything a calibration resolves.
    np.testing.assert_allclose(T, expm(twist_matrix(xi)), atol=max(angle, 1e-12))
    np.testing.assert_allclose(log_se3(T), xi, atol=1e-9)
    scipy_xi = RigidTransform.from_matrix(T).as_exp_coords()
    np.testing.assert_allclose(log_se3(T), np.concatenate([scipy_xi[3:], scipy_xi[:3]]), atol=1e-9)


@settings(max_examples=100)
@given(seeds, vectors, arrays(np.float64, 3, elements=st.floats(-1.0, 1.0)))
def test_adjoint_moves_a_twist_into_the_parent_frame(
    seed: int, rho: NDArray[np.float64], phi: NDArray[np.float64]
) -> None:
    T = random_transform(seed)
    xi = np.concatenate([rho, phi])
    expected = T @ expm(twist_matrix(xi)) @ invert(T)
    np.testing.assert_allclose(exp_se3(adjoint(T) @ xi), expected, atol=1e-9)


@given(
    arrays(np.float64, 3, elements=st.floats(-1.0, 1.0)).filter(lambda v: np.linalg.norm(v) > 1e-3)
)
def test_tangent_basis_completes_the_normal_to_a_right_handed_frame(
    direction: NDArray[np.float64],
) -> None:
    normal = direction / np.linalg.norm(direction)
    tangent = tangent_basis(normal)
    frame = np.column_stack([tangent, normal])
    np.testing.assert_allclose(frame.T @ frame, np.eye(3), atol=1e-12)
    assert np.linalg.det(frame) == pytest.approx(1.0)


@settings(max_examples=100)
@given(seeds, st.floats(-5.0, 5.0))
def test_plane_in_parent_holds_the_mapped_points(seed: int, offset: float) -> None:
    rng = np.random.default_rng(seed)
    normal = rng.normal(size=3)
    plane = Plane(normal=normal / np.linalg.norm(normal), offset=offset)
    # Points of the child frame on the plane: the foot of the origin plus tangent moves.
    on_plane = -offset * plane.normal + rng.normal(size=(5, 2)) @ tangent_basis(plane.normal).T
    T_parent_child = random_transform(seed)
    normal_parent, offset_parent = plane_in_parent(plane, T_parent_child)
    in_parent = on_plane @ T_parent_child[:3, :3].T + T_parent_child[:3, 3]
    np.testing.assert_allclose(in_parent @ normal_parent + offset_parent, 0.0, atol=1e-9)
    assert np.linalg.norm(normal_parent) == pytest.approx(1.0)


@given(
    arrays(np.float64, (2, 3), elements=st.floats(-1000.0, 1000.0)),
    st.sampled_from([0.02, 0.1, 0.7]),
)
def test_voxel_keys_name_the_cells(points: NDArray[np.float64], size: float) -> None:
    keys = voxel_keys(points, size, "voxel_size_m")
    cells = np.floor(points * (1.0 / size)).astype(np.int64)
    assert (keys[0] == keys[1]) == bool(np.all(cells[0] == cells[1]))
    # A neighbour's key is the key plus the packed offset, in every direction.
    for offset in np.array([[1, 0, 0], [0, -1, 0], [0, 0, -1], [-1, 1, -1]], dtype=np.int64):
        neighbour = voxel_keys(((cells[:1] + offset) + 0.5) * size, size, "voxel_size_m")
        assert neighbour[0] == keys[0] + pack_cells(offset)


def test_points_beyond_the_voxel_grid_are_refused_with_the_setting_to_change() -> None:
    with pytest.raises(BadInputError, match="use a larger cluster_radius_m"):
        voxel_keys(np.array([[0.0, 0.0, -3e4]]), 0.02, "cluster_radius_m")
    # Up to the grid's margin every point has a key.
    edge = ((1 << 20) - 2) * 0.02
    assert len(voxel_keys(np.array([[edge, -edge, 0.0]]), 0.02, "voxel_size_m")) == 1
