import numpy as np
import pytest

from pipeline import surfaces
from pipeline.downsample import voxel_downsample
from pipeline.surfaces import local_planes, local_surfaces, smallest_eigenvectors


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


def _cylinder(radius: float, n: int, noise: float, seed: int = 0) -> np.ndarray:
    """Points on the half of a vertical cylinder facing +x (what one LiDAR sees), 2 cm apart."""
    rng = np.random.default_rng(seed)
    angle = rng.uniform(-np.pi / 2, np.pi / 2, n)
    height = rng.uniform(0.0, 0.25, n)
    r = radius + rng.normal(0.0, noise, n)
    return np.column_stack([r * np.cos(angle), r * np.sin(angle), height])


def test_a_quadric_follows_a_curved_surface_that_a_plane_flattens() -> None:
    radius = 0.12
    points = _cylinder(radius, 600, noise=0.0)

    flat, _ = local_planes(points, 30, 10)
    curved, normals = local_planes(points, 30, quadric=True)

    def off_surface(p: np.ndarray) -> np.ndarray:
        return np.asarray(np.abs(np.hypot(p[:, 0], p[:, 1]) - radius))

    # The plane through a patch's centroid lies inside the cylinder (half a millimetre here, where
    # points are 1.3 cm apart; more on sparse or voxelised clouds)...
    assert np.median(off_surface(flat)) > 3e-4
    # ...the quadric stays on it, and its normals point away from the axis.
    assert np.median(off_surface(curved)) < 0.1 * np.median(off_surface(flat))
    radial = curved[:, :2] / np.hypot(curved[:, 0], curved[:, 1])[:, None]
    cos = np.abs(np.einsum("ni,ni->n", normals[:, :2], radial))
    assert np.median(cos) > np.cos(np.radians(1.0))


def test_a_quadric_smooths_range_noise_on_a_plane_like_the_plane_does() -> None:
    rng = np.random.default_rng(3)
    points = np.column_stack([rng.uniform(0, 0.5, (800, 2)), rng.normal(0.0, 0.01, 800)])
    flat, _ = local_planes(points, 30, 10)
    curved, normals = local_planes(points, 30, quadric=True)
    assert np.std(curved[:, 2]) < 0.5 * np.std(points[:, 2])
    assert np.std(curved[:, 2]) < 2.0 * np.std(flat[:, 2])
    assert np.median(np.abs(normals[:, 2])) > np.cos(np.radians(10.0))


def test_along_beams_moves_each_point_along_its_beam_onto_a_plane() -> None:
    rng = np.random.default_rng(5)
    yz = rng.uniform(-0.5, 0.5, size=(3000, 2))
    true = np.column_stack([np.full(3000, 3.0), yz])
    beams = true / np.linalg.norm(true, axis=1, keepdims=True)
    noisy = true + beams * rng.normal(0.0, 0.01, (3000, 1))
    projected, normals = local_planes(noisy, 30, quadric=True, along_beams=True)
    # Each point stays on its own beam ...
    cross = np.linalg.norm(np.cross(projected, beams), axis=1)
    assert np.max(cross) < 1e-9
    # ... and lands nearer the plane x = 3, with the plane's normal.
    assert np.std(projected[:, 0] - 3.0) < 0.4 * np.std(noisy[:, 0] - 3.0)
    assert np.median(np.abs(normals[:, 0])) > 0.995


def test_the_beam_quadric_keeps_the_quadrics_own_projection_on_the_way() -> None:
    points, _ = _oblique_plane_under_range_noise(3)
    beam = local_surfaces(points, 30, quadric=True, along_beams=True)
    projected, normals = local_planes(points, 30, quadric=True)
    assert beam.along_normals is not None
    np.testing.assert_array_equal(beam.along_normals, projected)
    np.testing.assert_array_equal(beam.normals, normals)
    assert not np.array_equal(beam.projected, projected)
    # Kept only where it is the quadric's: one pass, normals not taken along the beams.
    for kept in (
        local_surfaces(points, 30, quadric=True),
        local_surfaces(points, 30, quadric=True, along_beams=True, passes=2),
        local_surfaces(points, 30, quadric=True, along_beams=True, normals_along_beams=True),
    ):
        assert kept.along_normals is None


def _oblique_plane_under_range_noise(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The plane x + z = 3 (normal (1, 0, 1)/sqrt 2, 45 deg to the beams near the x axis) seen
    densely from the origin with 2 cm of range noise, voxelised at 2 cm as segmentation does: the
    points (a slab about as thick as a 30-point patch is wide) and the true normal."""
    rng = np.random.default_rng(seed)
    u, y = rng.uniform(-0.3, 0.3, size=(2, 100_000))
    true = np.column_stack([1.5 + u, y, 1.5 - u])
    beams = true / np.linalg.norm(true, axis=1, keepdims=True)
    noisy = true + beams * rng.normal(0.0, 0.02, (len(true), 1))
    return voxel_downsample(noisy, 0.02), np.array([1.0, 0.0, 1.0]) / np.sqrt(2)


def _median_error_deg(normals: np.ndarray, normal: np.ndarray) -> float:
    return float(np.degrees(np.median(np.arccos(np.clip(np.abs(normals @ normal), 0.0, 1.0)))))


def test_normals_along_beams_hold_where_range_noise_blurs_the_patch() -> None:
    noisy, normal = _oblique_plane_under_range_noise(6)
    _, least_spread = local_planes(noisy, 30)
    _, along_beams = local_planes(noisy, 30, normals_along_beams=True)
    # A patch about as deep (noise along the beams) as it is wide has no clear least-spread
    # direction; the plane fitted along the beams is still the surface's.
    assert _median_error_deg(least_spread, normal) > 25.0
    assert _median_error_deg(along_beams, normal) < 15.0


def test_normals_along_beams_are_exact_without_noise() -> None:
    rng = np.random.default_rng(7)
    u, y = rng.uniform(-0.4, 0.4, size=(2, 500))
    plane = np.column_stack([1.5 + u, y, 1.5 - u])
    _, normals = local_planes(plane, 15, normals_along_beams=True)
    np.testing.assert_allclose(np.abs(normals @ np.array([1.0, 0.0, 1.0])), np.sqrt(2), atol=1e-6)


def test_further_passes_thin_the_sheet_of_a_noisy_cylinder_without_moving_it() -> None:
    # A 15 cm cylinder 3 m ahead under 30 mm of range noise along the beams: one pass leaves
    # the projected points scattered about the surface; passes over the same neighbourhoods
    # draw them towards it, and the sheet's mean offset stays where one pass put it.
    rng = np.random.default_rng(0)
    radius, ahead, n = 0.15, 3.0, 4000
    angle = rng.uniform(np.pi / 2 + 0.3, 3 * np.pi / 2 - 0.3, n)
    true = np.column_stack(
        [ahead + radius * np.cos(angle), radius * np.sin(angle), rng.uniform(-0.3, 0.3, n)]
    )
    beams = true / np.linalg.norm(true, axis=1, keepdims=True)
    noisy = true + beams * rng.normal(0.0, 0.03, n)[:, None]

    def off_surface(passes: int) -> np.ndarray:
        projected, _ = local_planes(noisy, 80, quadric=True, passes=passes)
        return np.hypot(projected[:, 0] - ahead, projected[:, 1]) - radius

    one, four = off_surface(1), off_surface(4)
    assert four.std() < 0.6 * one.std()
    assert abs(four.mean() - one.mean()) < 0.001


@pytest.mark.parametrize(
    "model",
    [
        {"quadric": True, "along_beams": True},
        {"quadric": True},
        {"normals_along_beams": True, "along_beams": True, "quadric": True},
        {},
    ],
)
def test_fitting_in_chunks_of_points_changes_no_bit(
    model: dict[str, bool], monkeypatch: pytest.MonkeyPatch
) -> None:
    rng = np.random.default_rng(5)
    cloud = rng.normal(size=(500, 3)) * [1.0, 1.0, 0.02] + [2.0, 0.0, -0.5]
    whole = local_surfaces(cloud, 30, 10, **model)
    monkeypatch.setattr(surfaces, "ROWS_PER_CHUNK", 37)  # 14 chunks, the last of 19 points
    chunked = local_surfaces(cloud, 30, 10, **model)
    assert np.array_equal(chunked.projected, whole.projected)
    assert np.array_equal(chunked.normals, whole.normals)
    if whole.along_normals is None:
        assert chunked.along_normals is None
    else:
        assert chunked.along_normals is not None
        assert np.array_equal(chunked.along_normals, whole.along_normals)
