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
    partial = moved = 0
    for seed in range(3):
        world = make_world(short("people", stops=3, dwell_s=1.5), seed=seed, rate_scale=0.2)
        assert len(world.scene.walkers) == 2
        for i in range(len(world.spec.lidars)):
            T_world_lidar = world.T_world_lidar(i)
            for j in range(world.spec.motion.stops):
                seen = []
                for k in world.stop_scans(i, j):
                    labelled = world.simulate_scan(i, k)
                    moving = labelled.is_moving
                    seen.append(int(moving.sum()) > 3)
                    if not seen[-1]:
                        continue
                    assert np.all(labelled.object_index[moving] == NOT_STATIC)
                    pose = T_world_lidar(np.array([labelled.times[0]]))[0]
                    solid = moving & ~labelled.is_bleeding  # mixed returns float off the walker
                    points = labelled.points[solid] @ pose[:3, :3].T + pose[:3, 3]
                    middle = k * world.scan_period_ns(i) / _NS + 0.05
                    assert np.quantile(_distance_to_walkers(world, points, middle), 0.95) < 0.06
                    # Half a second earlier the walkers stood elsewhere: the points were not there.
                    before = _distance_to_walkers(world, points, middle - 0.5)
                    moved += int(np.median(before) > 0.2)
                # Seen in some scans of the stop and not in others.
                partial += int(any(seen) and not all(seen))
    assert moved >= 10
    assert partial >= 2


def _distance_to_walkers(world, points: np.ndarray, t: float) -> np.ndarray:  # type: ignore[no-untyped-def]
    return np.asarray(
        np.min([walker.at(t).distance(points) for walker in world.scene.walkers], axis=0)
    )


def test_labels_of_a_scene_without_walkers_say_nothing_moves(tiny_problem) -> None:  # type: ignore[no-untyped-def]
    _, truth = tiny_problem
    for labels in truth.labels.values():
        assert not labels.is_moving.any() and not labels.is_spurious.any()
