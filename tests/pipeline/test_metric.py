import numpy as np
import pytest

from pipeline.metric import (
    MetricConfig,
    SolutionComparison,
    capped_distances,
    compare_solutions,
    metric_error,
)


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


def _two_planes(rng: np.random.Generator) -> list[list[np.ndarray]]:
    """A reference and another LiDAR seeing the same 2 x 2 m floor patch, one stop."""
    big = np.column_stack([rng.uniform(-1.0, 1.0, (20_000, 2)), np.zeros(20_000)])
    return [[big], [big[:4000] + rng.normal(0.0, 0.002, (4000, 3))]]


Solution = tuple[np.ndarray, np.ndarray]


def _compare(
    objects: list[list[np.ndarray]], kept: Solution, other: Solution, block_m: float
) -> SolutionComparison:
    """`compare_solutions` as stage 4 calls it: each solution's distances measured once."""
    ours, theirs = (capped_distances(objects, *x, MetricConfig()) for x in (kept, other))
    return compare_solutions(ours, theirs, kept[1], other[1], block_m)


def test_two_solutions_that_agree_are_not_apart_and_fit_alike() -> None:
    objects = _two_planes(np.random.default_rng(2))
    solution = (np.stack([np.eye(4)]), np.stack([np.eye(4), np.eye(4)]))
    compared = _compare(objects, solution, solution, block_m=0.5)
    assert compared.apart_translation_m == 0.0 and compared.apart_rotation_deg == 0.0
    assert compared.difference_m == 0.0 and compared.separation_sigmas == 0.0
    assert compared.blocks >= 16


def test_a_solution_that_lifts_the_points_off_the_map_fits_worse_by_many_standard_errors() -> None:
    objects = _two_planes(np.random.default_rng(3))
    kept = (np.stack([np.eye(4)]), np.stack([np.eye(4), np.eye(4)]))
    lifted = np.eye(4)
    lifted[2, 3] = 0.03
    other = (kept[0], np.stack([np.eye(4), lifted]))
    compared = _compare(objects, kept, other, block_m=0.5)
    assert compared.apart_translation_m == pytest.approx(0.03)
    assert compared.difference_m == pytest.approx(0.03, abs=0.003)
    assert compared.separation_sigmas > 10.0
    np.testing.assert_array_equal(compared.other_T_ref_lidar, other[1])
    swapped = _compare(objects, other, kept, block_m=0.5)
    assert swapped.separation_sigmas < -10.0


def test_one_block_of_points_cannot_tell_two_solutions_apart() -> None:
    # Every point inside one 50 m block (the grid's cells start at the origin).
    objects = [
        [cloud + 5.0 for cloud in clouds] for clouds in _two_planes(np.random.default_rng(4))
    ]
    kept = (np.stack([np.eye(4)]), np.stack([np.eye(4), np.eye(4)]))
    lifted = np.eye(4)
    lifted[2, 3] = 0.03
    compared = _compare(objects, kept, (kept[0], np.stack([np.eye(4), lifted])), block_m=50.0)
    assert compared.blocks == 1 and np.isnan(compared.separation_sigmas)
