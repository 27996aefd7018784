import numpy as np

from pipeline.metric import MetricConfig, metric_error


def _plane(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.column_stack([rng.uniform(-0.3, 0.3, (n, 2)), np.zeros(n)])


def test_metric_is_the_mean_distance_to_the_reference_map() -> None:
    rng = np.random.default_rng(0)
    reference = _plane(rng, 200_000)
    other = _plane(rng, 2000) * [0.9, 0.9, 1.0] + [0.0, 0.0, 0.005]
    poses = np.stack([np.eye(4)])
    extrinsics = np.stack([np.eye(4), np.eye(4)])
    result = metric_error([[reference], [other]], poses, extrinsics, MetricConfig())
    assert abs(result.value - 0.005) < 0.0003
    assert result.points == (200_000, 2000)
    assert np.isnan(result.per_lidar[0])


def test_far_points_count_at_the_cap_and_empty_maps_give_nan() -> None:
    rng = np.random.default_rng(1)
    reference = _plane(rng, 1000)
    far = reference[:10] + np.array([0.0, 0.0, 5.0])
    poses, extrinsics = np.stack([np.eye(4)]), np.stack([np.eye(4), np.eye(4)])
    capped = metric_error([[reference], [far]], poses, extrinsics, MetricConfig(max_distance_m=0.1))
    assert capped.value == 0.1
    empty = metric_error([[reference], [far[:0]]], poses, extrinsics, MetricConfig())
    assert np.isnan(empty.value)
