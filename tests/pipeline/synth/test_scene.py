"""Scene building: objects apart from each other and from the robot's path, reproducible."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.synth.scene import ObjectKind, Ring, SceneSpec, build_scene, place_objects


def _objects(seed: int, spec: SceneSpec, keep_out: tuple[float, float] = (0.0, 0.0)):  # type: ignore[no-untyped-def]
    return place_objects(spec, np.random.default_rng(seed), keep_out)


def test_objects_stand_apart_outside_the_robot_path() -> None:
    spec = SceneSpec(
        object_kinds=tuple(ObjectKind),
        rings=(
            Ring(r_min_m=0.3, r_max_m=1.5, count=(5, 5)),
            Ring(r_min_m=3.2, r_max_m=4.5, count=(12, 12)),
        ),
    )
    robot_radius = 0.5 * math.hypot(*spec.robot_size_m[:2])
    for seed in range(5):
        objects = _objects(seed, spec, keep_out=(2.5, 2.5))
        assert len(objects) == 17
        xy = np.array([obj.T_world_object[:2, 3] for obj in objects])
        r_xy = np.array([obj.radius_xy for obj in objects])
        gaps = np.linalg.norm(xy[:, None] - xy[None], axis=2) - r_xy[:, None] - r_xy[None]
        np.fill_diagonal(gaps, np.inf)
        assert gaps.min() >= spec.object_gap_m
        distance_to_path = np.abs(np.linalg.norm(xy, axis=1) - 2.5) - r_xy
        assert distance_to_path.min() >= robot_radius + spec.robot_clearance_m
        assert all(obj.T_world_object[2, 3] == pytest.approx(0.125) for obj in objects)
        assert all(obj.bounding_radius >= obj.radius_xy for obj in objects)


def test_objects_are_reproducible_for_a_seed_and_differ_across_seeds() -> None:
    spec = SceneSpec(object_kinds=tuple(ObjectKind))
    first, again, other = _objects(1, spec), _objects(1, spec), _objects(2, spec)
    assert [o.to_json() for o in first] == [o.to_json() for o in again]
    assert [o.to_json() for o in first] != [o.to_json() for o in other]


def test_overcrowded_ring_is_refused_with_advice() -> None:
    spec = SceneSpec(rings=(Ring(r_min_m=1.0, r_max_m=1.2, count=(40, 40)),))
    with pytest.raises(ConfigError, match="lower its object count"):
        _objects(0, spec)


def test_built_model_holds_floor_objects_and_robot() -> None:
    spec = SceneSpec(object_kinds=tuple(ObjectKind))
    objects = _objects(4, spec)
    scene = build_scene(spec, objects, {"lidar_front": np.eye(4)})
    assert scene.model.ngeom == 1 + len(objects) + 1
    assert scene.model.nsite == 1
    assert sorted(scene.geom_object[scene.geom_object >= 0].tolist()) == list(range(len(objects)))
    assert scene.model.body(scene.robot_body_id).name == "robot"
