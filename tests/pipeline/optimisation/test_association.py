"""Association on a wall at x = 1 m in G, seen by two LiDARs at two stops (all stops at G)."""

import numpy as np
import pytest

from pipeline.optimisation import OptimisationConfig
from pipeline.optimisation.association import associate
from pipeline.optimisation.objective import JointObjective
from pipeline.transforms import make_transform

GRID = np.array([(0.0, y, z) for y in np.arange(-0.5, 0.51, 0.1) for z in np.arange(0, 1, 0.1)])
WALL_NORMAL = np.array([1.0, 0.0, 0.0])


def wall_seen_from(x_lidar: float, rng: np.random.Generator) -> np.ndarray:
    """The wall's points in the frame of a LiDAR at (x_lidar, 0, 0), jittered along the wall."""
    jitter = rng.uniform(-0.02, 0.02, size=GRID.shape) * [0.0, 1.0, 1.0]
    return GRID + jitter + [1.0 - x_lidar, 0.0, 0.0]


def objective(x_lidar_1: float, **update: object) -> tuple[JointObjective, np.ndarray]:
    rng = np.random.default_rng(0)
    objects = [
        [wall_seen_from(0.0, rng), wall_seen_from(0.0, rng)],
        [wall_seen_from(x_lidar_1, rng), np.zeros((0, 3))],
    ]
    normals = [[np.tile(WALL_NORMAL, (len(c), 1)) for c in row] for row in objects]
    config = OptimisationConfig(max_points_per_cloud=None, **update)  # type: ignore[arg-type]
    built = JointObjective.build(objects, None, None, 2, config, normals)
    lidars = np.stack([np.eye(4), make_transform(np.eye(3), [x_lidar_1, 0.0, 0.0])])
    return built, lidars


def test_a_reference_point_is_paired_with_the_map_of_another_stop() -> None:
    built, lidars = objective(0.0)
    pairs = associate(built, built.place(np.stack([np.eye(4)] * 2), lidars))
    reference_sources = built.sources.lidar[pairs.source] == 0
    assert reference_sources.sum() == 2 * len(GRID)
    source_stop = built.sources.stop[pairs.source]
    target_stop = built.reference.stop[pairs.target]
    assert np.all(source_stop[reference_sources] != target_stop[reference_sources])
    # The other LiDAR's points go to the reference map, at any stop.
    assert np.all(built.reference.lidar[pairs.target] == 0)
    assert (~reference_sources).sum() == len(GRID)
    assert pairs.cross_error < 0.03


def test_pairs_beyond_the_gate_are_dropped_but_still_measured() -> None:
    built, lidars = objective(0.0, max_correspondence_m=0.05)
    lidars[1] = make_transform(np.eye(3), [0.3, 0.0, 0.0])  # LiDAR 1's wall lands 30 cm behind
    pairs = associate(built, built.place(np.stack([np.eye(4)] * 2), lidars))
    assert not np.any(built.sources.lidar[pairs.source] == 1)
    assert pairs.cross_error == pytest.approx(0.3, abs=0.01)


@pytest.mark.parametrize(("gate_deg", "paired"), [(45.0, False), (None, True)])
def test_the_back_of_a_wall_is_not_its_front(gate_deg: float | None, paired: bool) -> None:
    # LiDAR 1 stands behind the wall: its normals face it, against the reference's.
    built, lidars = objective(2.0, max_normal_angle_deg=gate_deg)
    pairs = associate(built, built.place(np.stack([np.eye(4)] * 2), lidars))
    assert np.any(built.sources.lidar[pairs.source] == 1) == paired


def test_every_lidar_pairs_each_lidars_points_with_every_other_lidars_map() -> None:
    built, lidars = objective(0.0, cross_pairs="every_lidar")
    pairs = associate(built, built.place(np.stack([np.eye(4)] * 2), lidars))
    source = built.sources.lidar[pairs.source]
    target = built.reference.lidar[pairs.target]
    # The reference's points of both stops meet LiDAR 1's map (one stop) as well as their own
    # map of the other stop; LiDAR 1 saw one stop, so it has no self pair.
    assert np.count_nonzero((source == 0) & (target == 1)) == 2 * len(GRID)
    assert np.count_nonzero((source == 0) & (target == 0)) == 2 * len(GRID)
    assert np.count_nonzero((source == 1) & (target == 0)) == len(GRID)
    assert not np.any((source == 1) & (target == 1))


def test_eq_11_stays_the_reference_maps_alone_with_every_lidar() -> None:
    placed_error = []
    for cross_pairs in ("reference", "every_lidar"):
        built, lidars = objective(0.0, cross_pairs=cross_pairs, max_correspondence_m=0.05)
        lidars[1] = make_transform(np.eye(3), [0.3, 0.0, 0.0])
        pairs = associate(built, built.place(np.stack([np.eye(4)] * 2), lidars))
        placed_error.append(pairs.cross_error)
    assert placed_error[1] == pytest.approx(placed_error[0])
    assert placed_error[0] == pytest.approx(0.3, abs=0.01)


@pytest.mark.parametrize(("n_lidars", "every_lidar"), [(2, False), (3, True), (4, True)])
def test_auto_pairs_with_every_lidars_map_from_three_lidars(
    n_lidars: int, every_lidar: bool
) -> None:
    rng = np.random.default_rng(1)
    objects = [[wall_seen_from(0.0, rng), wall_seen_from(0.0, rng)] for _ in range(n_lidars)]
    normals = [[np.tile(WALL_NORMAL, (len(c), 1)) for c in row] for row in objects]
    config = OptimisationConfig(max_points_per_cloud=None, cross_pairs="auto")
    assert config.pairs_every_lidar(n_lidars) == every_lidar
    built = JointObjective.build(objects, None, None, 2, config, normals)
    pairs = associate(
        built, built.place(np.stack([np.eye(4)] * 2), np.stack([np.eye(4)] * n_lidars))
    )
    targets = set(built.reference.lidar[pairs.target].tolist())
    assert targets == (set(range(n_lidars)) if every_lidar else {0})
