import numpy as np

from pipeline.downsample import voxel_downsample
from pipeline.segmentation import SegmentationConfig
from pipeline.surface_bias import range_noise_from_smoothing, smoothing_offsets
from pipeline.surfaces import local_planes

AXIS_XY = np.array([2.0, 0.0])
"""A vertical cylinder 2 m ahead of the sensor (at the origin)."""


def _cylinder_seen_from_origin(radius: float, noise: float, seed: int = 0) -> np.ndarray:
    """Returns of a vertical cylinder of `radius` on the axis `AXIS_XY`, from beams fanned out of
    the origin over its silhouette, with Gaussian range noise `noise` (m) along each beam,
    voxelised at 2 cm as segmentation does."""
    rng = np.random.default_rng(seed)
    half_angle = np.arcsin(radius / np.linalg.norm(AXIS_XY)) * 0.95
    azimuth = rng.uniform(-half_angle, half_angle, 60_000)
    elevation = rng.uniform(-0.02, 0.12, 60_000)
    beams = np.column_stack(
        [
            np.cos(azimuth) * np.cos(elevation),
            np.sin(azimuth) * np.cos(elevation),
            np.sin(elevation),
        ]
    )
    # The nearer root of |t b_xy - axis| = radius along each beam.
    b_xy = beams[:, :2]
    along = b_xy @ AXIS_XY
    norm2 = np.einsum("ni,ni->n", b_xy, b_xy)
    t = (along - np.sqrt(along**2 - norm2 * (AXIS_XY @ AXIS_XY - radius**2))) / norm2
    t += rng.normal(0.0, noise, len(t))
    return voxel_downsample(beams * t[:, None], 0.02)


def _fit(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return local_planes(points, 80, quadric=True)


def test_segmentation_takes_the_offset_back_only_when_asked() -> None:
    from pipeline.segmentation import _smoothed

    raw = _cylinder_seen_from_origin(0.15, noise=0.03, seed=1)
    quadric = SegmentationConfig(surface_model="quadric")  # the offset the bootstrap measures
    fitted = _smoothed(raw, quadric)
    plain, normals = fitted.projected, fitted.normals
    debiased_fit = _smoothed(raw, quadric.model_copy(update={"surface_debias": "bootstrap"}))
    debiased, debiased_normals = debiased_fit.projected, debiased_fit.normals
    np.testing.assert_array_equal(plain, _fit(raw)[0])
    np.testing.assert_array_equal(debiased_normals, normals)
    # Moved along the normals only, by the offsets the same draw measures.
    offsets = smoothing_offsets(
        raw, plain, normals, lambda p: _fit(p)[0], 80, np.random.default_rng(0)
    )
    assert np.max(np.abs(offsets)) > 1e-3
    np.testing.assert_allclose(debiased, plain - offsets[:, None] * normals)


def test_without_noise_there_is_nothing_to_take_back() -> None:
    raw = _cylinder_seen_from_origin(0.15, noise=0.0)
    smoothed, normals = _fit(raw)
    offsets = smoothing_offsets(
        raw, smoothed, normals, lambda p: _fit(p)[0], 80, np.random.default_rng(0)
    )
    assert np.max(np.abs(offsets)) < 5e-4


def test_the_range_noise_is_what_smoothing_removed_along_the_beams() -> None:
    rng = np.random.default_rng(2)
    # A wall 3 m ahead, facing the sensor; noise along the beams.
    yz = rng.uniform(-0.5, 0.5, (4000, 2))
    beams = np.column_stack([np.full(4000, 3.0), yz])
    beams /= np.linalg.norm(beams, axis=1, keepdims=True)
    ranges = 3.0 / beams[:, 0] + rng.normal(0.0, 0.02, 4000)
    raw = beams * ranges[:, None]
    smoothed, normals = _fit(raw)
    sigma = range_noise_from_smoothing(raw, smoothed, normals, beams)
    assert sigma is not None
    assert 0.015 < sigma < 0.025


def test_too_few_facing_points_measure_no_noise() -> None:
    raw = _cylinder_seen_from_origin(0.15, noise=0.03)[:20]
    smoothed, normals = local_planes(raw, 10, quadric=True)
    beams = smoothed / np.linalg.norm(smoothed, axis=1, keepdims=True)
    assert range_noise_from_smoothing(raw, smoothed, normals, beams) is None
    offsets = smoothing_offsets(
        raw,
        smoothed,
        normals,
        lambda p: local_planes(p, 10, quadric=True)[0],
        10,
        np.random.default_rng(0),
    )
    np.testing.assert_array_equal(offsets, 0.0)
