"""People walking by: labelled as moving, on a walker where it is at each scan's time, in some
scans of a stop and not in others, and never in the robot's way."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.synth import make_world
from pipeline.synth.scene import NOT_STATIC
from pipeline.synth.walkers import Walker, WalkerKind, WalkersSpec, draw_walkers
from tests.pipeline.synth.worlds import short

_NS = 1_000_000_000


def test_a_walker_paces_its_way_at_its_speed() -> None:
    walker = Walker(
        WalkerKind.PERSON,
        {"radius": 0.2, "height": 1.7},
        np.array([1.0, 2.0]),
        np.array([4.0, 2.0]),
        speed_mps=1.2,
        phase=0.1,
        reflectivity=0.5,
    )
    t = np.arange(0.0, 20.0, 0.01)
    xy, heading = walker.positions(t)
    assert xy[:, 0].min() == pytest.approx(1.0, abs=0.02) and xy[:, 0].max() == pytest.approx(
        4.0, abs=0.02
    )
    np.testing.assert_allclose(xy[:, 1], 2.0)
    speed = np.linalg.norm(np.diff(xy, axis=0), axis=1) / 0.01
    assert np.median(speed) == pytest.approx(1.2)
    assert set(np.round(np.cos(heading)).astype(int).tolist()) == {-1, 1}  # there and back
    assert walker.at(3.0, ground_m=0.01).T_world_object[2, 3] == pytest.approx(0.01 + 0.85)
    assert Walker.from_json(walker.to_json()).to_json() == walker.to_json()


def test_walkers_keep_out_of_the_robot_path() -> None:
    spec = WalkersSpec(count=(3, 3), kinds=(WalkerKind.PERSON, WalkerKind.CART))
    band = (-0.8, 0.8)
    for seed in range(10):
        for walker in draw_walkers(spec, np.random.default_rng(seed), band):
            way = walker.start + np.linspace(0, 1, 200)[:, None] * (walker.end - walker.start)
            assert np.linalg.norm(way, axis=1).min() >= band[1] + walker.radius_xy - 1e-9
            assert 0.5 <= walker.speed_mps <= 1.5


def test_no_walkway_clear_of_the_robot_is_refused_with_advice() -> None:
    spec = WalkersSpec(offset_m=(0.1, 0.2))
    with pytest.raises(ConfigError, match="widen the walkers' offset_m"):
        draw_walkers(spec, np.random.default_rng(0), (-1.0, 1.0))


def test_moving_points_are_labelled_on_the_walker_where_it_is_at_each_scan() -> None:
    world = make_world(short("people", stops=2, dwell_s=1.5), seed=3, rate_scale=0.3)
    scene = world.scene
    assert len(scene.walkers) == 2
    in_view: dict[tuple[int, int], list[bool]] = {}
    moved = 0
    for i in range(len(world.spec.lidars)):
        T_world_lidar = world.T_world_lidar(i)
        for j in range(world.spec.motion.stops):
            for k in world.stop_scans(i, j):
                labelled = world.simulate_scan(i, k)
                moving = labelled.is_moving
                in_view.setdefault((i, j), []).append(int(moving.sum()) > 5)
                if moving.sum() <= 5:
                    continue
                assert np.all(labelled.object_index[moving] == NOT_STATIC)
                pose = T_world_lidar(np.array([labelled.times[0]]))[0]
                points = labelled.points[moving] @ pose[:3, :3].T + pose[:3, 3]
                middle = (labelled.stamp_ns - world.spec.start_time_ns) / _NS + 0.05
                now = _distance_to_walkers(world, points, middle)
                assert np.quantile(now, 0.95) < 0.06
                # Half a second earlier the walkers stood elsewhere: the points were not there.
                before = _distance_to_walkers(world, points, middle - 0.5)
                moved += int(np.median(before) > 0.2)
    assert moved >= 3
    # Each stop sees walkers in some scans and not in others for at least one LiDAR.
    assert any(any(seen) and not all(seen) for seen in in_view.values()), in_view


def _distance_to_walkers(world, points: np.ndarray, t: float) -> np.ndarray:  # type: ignore[no-untyped-def]
    return np.min([walker.at(t).distance(points) for walker in world.scene.walkers], axis=0)


def test_labels_of_a_scene_without_walkers_say_nothing_moves(tiny_problem) -> None:  # type: ignore[no-untyped-def]
    _, truth = tiny_problem
    for labels in truth.labels.values():
        assert not labels.is_moving.any() and not labels.is_spurious.any()
