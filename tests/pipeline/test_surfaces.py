import numpy as np

from pipeline.surfaces import local_planes, smallest_eigenvectors


def test_smallest_eigenvectors_match_eigh() -> None:
    rng = np.random.default_rng(3)
    A = rng.normal(size=(200, 3, 3))
    covariance = A @ np.swapaxes(A, 1, 2)
    expected = np.linalg.eigh(covariance)[1][:, :, 0]
    result = smallest_eigenvectors(covariance)
    # Eigenvectors are defined up to sign.
    np.testing.assert_allclose(np.abs(np.einsum("ni,ni->n", result, expected)), 1.0, atol=1e-6)


def test_local_planes_flatten_a_noisy_plane_onto_itself() -> None:
    rng = np.random.default_rng(4)
    xy = rng.uniform(-0.5, 0.5, size=(2000, 2))
    noisy = np.column_stack([xy, 0.3 + rng.normal(0.0, 0.01, 2000)])
    projected, normals = local_planes(noisy, 30)
    assert np.median(np.abs(normals[:, 2])) > 0.995
    assert np.all(np.abs(normals[:, 2]) > 0.9)
    # The projection removes most of the noise across the plane.
    assert np.std(projected[:, 2] - 0.3) < 0.4 * np.std(noisy[:, 2] - 0.3)
