"""The closed room: walls at their declared distance in the clouds, doorways, shelves, clear
of the robot; surfaces of different reflectivity give different intensities."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from pipeline.errors import ConfigError
from pipeline.synth import make_world
from pipeline.synth.objects import ObjectRole, SceneObject
from pipeline.synth.room import RoomSpec, build_room
from pipeline.transforms import apply
from tests.pipeline.synth.worlds import short, small_problem


def _by_role(objects: tuple[SceneObject, ...], role: ObjectRole) -> list[int]:
    return [k for k, obj in enumerate(objects) if obj.role is role]


def test_room_has_walls_doorways_and_tall_shelves_in_the_spec() -> None:
    spec = RoomSpec()
    for seed in range(5):
        room = build_room(spec, np.random.default_rng(seed), (-1.0, 0.8))
        walls = [s for s in room.structures if s.role is ObjectRole.WALL]
        shelves = [s for s in room.structures if s.role is ObjectRole.SHELF]
        x_min, x_max, y_min, y_max = room.inner
        assert all(2.0 <= d <= 5.0 for d in (-x_min, x_max, -y_min, y_max))
        # Four walls, split at a doorway or two (with a lintel above where the wall is taller).
        assert len(walls) >= 4 + 1
        tops = {round(w.T_world_object[2, 3] + 0.5 * w.dimensions["z"], 9) for w in walls}
        assert len(tops) == 1 and 2.0 <= tops.pop() <= 3.0
        assert shelves, "shelves stand along the walls"
        for shelf in shelves:
            assert 1.5 <= shelf.dimensions["z"] <= 2.0 and 0.4 <= shelf.dimensions["y"] <= 0.6
            assert shelf.footprint_gap(np.zeros(2), 0.0) > 0.8


def test_walls_lie_at_their_declared_distance_in_the_clouds() -> None:
    problem, truth = small_problem("room", seed=1, stops=4, rate_scale=0.1)
    walls = _by_role(truth.objects, ObjectRole.WALL)
    seen = 0
    for j, stop in enumerate(problem.stops):
        T_world_base = truth.stops[j].T_odom_base_true
        for frame in problem.frames:
            labels = truth.stop_labels(j, frame)
            world = apply(T_world_base @ truth.lidar(frame).T_base_lidar_true, stop.clouds[frame])
            for k in walls:
                mine = (labels.object_index == k) & ~labels.is_bleeding
                if mine.sum() < 20:
                    continue
                seen += 1
                wall = truth.objects[k]
                # A wall box's y axis is its thickness; the inner face is the nearer side.
                normal = wall.T_world_object[:3, 1]
                face = abs(wall.T_world_object[:3, 3] @ normal) - 0.5 * wall.dimensions["y"]
                assert 2.0 <= face <= 5.0
                distance = np.abs(world[mine] @ normal)
                assert np.median(distance) == pytest.approx(face, abs=0.01)
                assert np.quantile(np.abs(distance - face), 0.95) < 0.06
    assert seen >= 4


def test_surfaces_of_different_reflectivity_differ_in_intensity() -> None:
    world = make_world(short("room"), seed=1, rate_scale=0.2)
    scans = [world.simulate_scan(i, k) for i in range(2) for k in range(0, 6)]
    intensity = np.concatenate([s.intensity for s in scans]).astype(np.float64)
    index = np.concatenate([s.object_index for s in scans])
    reflectivity = {-1: world.spec.scene.floor_reflectivity}
    reflectivity |= {k: obj.reflectivity for k, obj in enumerate(world.scene.objects)}
    medians = {k: np.median(intensity[index == k]) for k in reflectivity if (index == k).sum() > 30}
    assert len(medians) >= 4
    for k, median in medians.items():
        assert np.all(intensity[index == k] <= 255.0 * reflectivity[k] + 1e-3)
        assert median > 0
    # Intensity follows the surface's reflectivity (the angle of incidence scatters it).
    keys = sorted(medians)
    order = np.argsort([reflectivity[k] for k in keys])
    ranked = np.argsort(np.argsort([medians[k] for k in keys]))
    assert np.corrcoef(np.arange(len(keys)), ranked[order])[0, 1] > 0.6


def test_objects_stand_inside_the_room_clear_of_walls_and_shelves() -> None:
    for seed in range(4):
        world = make_world("room", seed)
        structures = [o for o in world.scene.objects if o.role is not ObjectRole.OBJECT]
        for obj in world.scene.objects:
            if obj.role is ObjectRole.OBJECT:
                xy = obj.T_world_object[:2, 3]
                assert all(s.footprint_gap(xy, obj.radius_xy) > 0 for s in structures)


def test_a_room_cutting_the_robot_path_is_refused_with_advice() -> None:
    with pytest.raises(ConfigError, match="raise the room's wall_distance_m"):
        build_room(RoomSpec(), np.random.default_rng(0), (1.5, 3.5))


def test_a_room_spec_out_of_order_is_refused() -> None:
    with pytest.raises(ValidationError, match="wall_height_m must be"):
        RoomSpec(wall_height_m=(3.0, 2.0))
    with pytest.raises(ValidationError, match="farther from the origin than a shelf is deep"):
        RoomSpec(wall_distance_m=(0.5, 5.0))
