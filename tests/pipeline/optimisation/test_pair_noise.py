"""Per-LiDAR-pair residual sigmas on a wall at x = 1 m in G, the reference's points on it within
2 mm, LiDAR 1's scattered 20 mm across it (both stops at G)."""

from dataclasses import dataclass

import numpy as np

from pipeline.optimisation import OptimisationConfig
from pipeline.optimisation.association import Pairs, associate
from pipeline.optimisation.objective import JointObjective
from pipeline.optimisation.pair_noise import with_lidar_pair_sigmas
from pipeline.optimisation.residuals import pair_weights_and_costs, point_residuals
from tests.pipeline.optimisation.test_association import WALL_NORMAL, wall_seen_from


def _scattered(points: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    scattered: np.ndarray = points + rng.normal(0.0, sigma, (len(points), 1)) * WALL_NORMAL
    return scattered


@dataclass(frozen=True)
class WallPairs:
    objective: JointObjective
    plain: Pairs
    measured: Pairs
    sigma: np.ndarray
    residual: np.ndarray
    from_lidar_1: np.ndarray


def _pairs_on_the_wall(behind: int = 0) -> WallPairs:
    """`behind`: LiDAR 1 also sees that many times its wall points on a second wall 0.3 m
    behind the first, which the reference does not see (its pairs there are 0.3 m long), and
    the reference sees its wall as many times more densely."""

    def seen(sigma: float, copies: int) -> np.ndarray:
        return np.vstack([_scattered(wall_seen_from(0.0, rng), sigma, rng) for _ in range(copies)])

    rng = np.random.default_rng(1)
    objects = [
        [seen(0.002, 1 + behind) for _ in range(2)],
        [
            np.vstack([seen(0.020, 1), *[wall_seen_from(-0.3, rng) for _ in range(behind)]])
            for _ in range(2)
        ],
    ]
    normals = [[np.tile(WALL_NORMAL, (len(c), 1)) for c in row] for row in objects]
    config = OptimisationConfig(max_points_per_cloud=None, pair_weights="lidar_pairs")
    built = JointObjective.build(objects, None, None, 2, config, normals)
    placed = built.place(np.stack([np.eye(4)] * 2), np.stack([np.eye(4)] * 2))
    plain = associate(built, placed)
    measured = with_lidar_pair_sigmas(built, plain, placed)
    assert plain.sigma is None and measured.sigma is not None
    return WallPairs(
        built,
        plain,
        measured,
        measured.sigma,
        point_residuals(config.residual, measured, placed),
        built.sources.lidar[measured.source] == 1,
    )


def test_each_pair_of_lidars_gets_the_scatter_of_its_residuals() -> None:
    wall = _pairs_on_the_wall()
    sigma, from_lidar_1 = wall.sigma, wall.from_lidar_1
    # Reference against itself: 2 mm on both sides; LiDAR 1 against it: 20 mm and 2 mm.
    ratio = sigma[from_lidar_1].mean() / sigma[~from_lidar_1].mean()
    np.testing.assert_allclose(ratio, np.hypot(20, 2) / np.hypot(2, 2), rtol=0.2)
    assert np.ptp(sigma[from_lidar_1]) == 0.0 and np.ptp(sigma[~from_lidar_1]) == 0.0


def test_a_group_s_sigma_is_its_inliers_scatter_however_many_far_pairs_it_holds() -> None:
    # Three far pairs for every near one: a median over all would read 0.3 m.
    wall = _pairs_on_the_wall(behind=3)
    near = np.linalg.norm(wall.residual, axis=1) < 0.1
    to_reference = wall.from_lidar_1 & (wall.objective.reference.lidar[wall.measured.target] == 0)
    assert np.count_nonzero(to_reference & ~near) > 2 * np.count_nonzero(to_reference & near)
    own_reference = ~wall.from_lidar_1 & (wall.objective.reference.lidar[wall.measured.target] == 0)
    ratio = wall.sigma[to_reference].mean() / wall.sigma[own_reference].mean()
    np.testing.assert_allclose(ratio, np.hypot(20, 2) / np.hypot(2, 2), rtol=0.2)


def test_the_pairs_weigh_by_their_sigma_and_as_much_as_before_on_average() -> None:
    wall = _pairs_on_the_wall()
    unit = wall.objective.config.point_sigma_m
    np.testing.assert_allclose(np.mean(1.0 / wall.sigma**2), 1.0 / unit**2)
    # A kernel far wider than any residual: the weights are whitened least squares'.
    weight, _ = pair_weights_and_costs(wall.objective, wall.measured, wall.residual, scale=10.0)
    np.testing.assert_allclose(weight, 1.0 / wall.sigma**2, rtol=1e-4)
    uniform, _ = pair_weights_and_costs(wall.objective, wall.plain, wall.residual, scale=10.0)
    np.testing.assert_allclose(uniform, 1.0 / unit**2, rtol=1e-4)
    assert weight[wall.from_lidar_1].mean() < weight[~wall.from_lidar_1].mean() / 10
