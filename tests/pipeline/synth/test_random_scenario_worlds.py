"""The world axis of the randomised scenarios: opt-in (a seed drawn without it is what it was
before the axis existed), the same draw in every world but for the world, and the world in the
class, the spec and the truth."""

from __future__ import annotations

import hashlib
import json
from typing import Any

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.synth import make_world
from pipeline.synth.objects import ObjectRole
from pipeline.synth.random_scenario import (
    RANDOM_WORLD,
    RANGES,
    WORLDS,
    random_scenario,
    world_name,
)
from pipeline.synth.scenarios import ScenarioSpec, WorldKind
from tests.pipeline.synth.test_existing_renders import _digest

# Taken on main before the world axis existed (commit 117e26a): `_spec_digest` over seeds
# 1000-1099, and the render digest of `test_existing_renders` for every 13th scan of seed 1000 at
# rate 0.02. Floats are rounded to 1e-6 (as the render digest rounds to micrometres): a digest of
# their full repr differed between two fresh installs whose code drew the same scenarios.
SPECS_1000_1099 = "6a2d3e634ae94bde41a04dfc96902c9c2e84e2bdc4643ff5b135e74be3827f73"
RENDER_1000 = "7816e1ef7b34fb96c3983346c1eda52392f34e59dff5f4784a593d0a921dc24f"
WORLD_OPTIONS = ("room", "walkers", "floor", "dust")
SEEDS = range(1000, 1012)


def _spec_digest(spec: ScenarioSpec) -> str:
    """sha256 of the spec's JSON with every float rounded to 1e-6 (ints and strings exact)."""

    def rounded(value: Any) -> Any:
        if isinstance(value, float):
            return round(value, 6) + 0.0  # + 0.0: -0.0 and 0.0 alike
        if isinstance(value, list):
            return [rounded(item) for item in value]
        if isinstance(value, dict):
            return {key: rounded(item) for key, item in value.items()}
        return value

    canonical = json.dumps(rounded(spec.model_dump(mode="json")), sort_keys=True)
    return hashlib.sha256(canonical.encode()).hexdigest()


def _without_world(spec: ScenarioSpec) -> dict[str, Any]:
    """The spec's dump less everything the world sets."""
    doc = spec.model_dump(mode="json")
    for key in ("world", "scenario_class", "description"):
        doc.pop(key)
    for key in WORLD_OPTIONS:
        doc["scene"].pop(key)
    return doc


def test_a_seed_drawn_without_a_world_is_what_it_was_before_worlds() -> None:
    sha = hashlib.sha256()
    for seed in range(1000, 1100):
        sha.update(_spec_digest(random_scenario(seed)).encode())
    assert sha.hexdigest() == SPECS_1000_1099
    world = make_world(random_scenario(1000), 1000, 0.02)
    scans = [
        world.simulate_scan(i, k)
        for i in range(len(world.spec.lidars))
        for k in range(0, world.scan_count(i), 13)
    ]
    assert _digest(scans) == RENDER_1000


@pytest.mark.parametrize("world", WORLDS)
def test_a_world_changes_only_the_world(world: str) -> None:
    options = {
        "open": set(),
        "room": {"room"},
        "people": {"walkers"},
        "uneven-floor": {"floor"},
        "dust": {"dust"},
        "factory": set(WORLD_OPTIONS),
    }[world]
    for seed in SEEDS:
        base, spec = random_scenario(seed), random_scenario(seed, world=world)
        assert _without_world(spec) == _without_world(base)
        assert spec.scenario_class == f"{base.scenario_class}/{world}"
        assert world_name(spec) == world and base.world is WorldKind.OPEN_FLOOR
        assert {key for key in WORLD_OPTIONS if getattr(spec.scene, key) is not None} == options
        # The seed's other draws (extrinsics, odometry errors) do not see the world.
        a, b = make_world(base, seed), make_world(spec, seed)
        np.testing.assert_array_equal(np.stack(a.T_base_lidar_initial), b.T_base_lidar_initial)
        np.testing.assert_array_equal(a.odometry_errors, b.odometry_errors)
        # The low objects are the open floor's, less those a wall, shelf or walkway displaces.
        low = [o for o in b.scene.objects if o.role is ObjectRole.OBJECT]
        open_xy = {tuple(np.round(o.T_world_object[:2, 3], 9)) for o in a.scene.objects}
        assert {tuple(np.round(o.T_world_object[:2, 3], 9)) for o in low} <= open_xy
        if not options & {"room", "walkers"}:
            assert len(low) == len(a.scene.objects)
        if "room" in options:
            assert any(o.role is ObjectRole.WALL for o in b.scene.objects)
        if "walkers" in options:
            assert 1 <= len(b.scene.walkers) <= 3
            assert all(0.5 <= w.speed_mps <= 1.5 for w in b.scene.walkers)


def test_the_room_keeps_clear_of_the_path_and_is_2_to_5_m_round_a_turn_in_place() -> None:
    for seed in range(1000, 1040):
        spec = random_scenario(seed, world="factory")
        room, walkers = spec.scene.room, spec.scene.walkers
        assert room is not None and walkers is not None
        reach = spec.scene.robot_band(spec.motion.radius_band_m())[1]
        depth = room.shelf_depth_m[1] + room.shelf_gap_m[1]
        assert room.wall_distance_m[0] >= reach + depth + RANGES.walkway_aisle_m - 1e-9
        assert walkers.offset_m[0] > reach
        if spec.scenario_class.startswith("rotate"):
            room_only = random_scenario(seed, world="room").scene.room
            assert room_only is not None and room_only.wall_distance_m == (2.0, 5.0)
        assert room.wall_height_m == (2.0, 3.0) and room.shelf_height_m == (1.5, 2.0)


def test_the_world_round_trips_through_the_truth() -> None:
    seed = 1003
    spec = random_scenario(seed, world="factory")
    truth = make_world(spec, seed, 0.02).truth()
    doc = json.loads(json.dumps(truth.to_json()))
    assert ScenarioSpec.model_validate(doc["spec"]) == spec
    assert doc["spec"]["world"] == "factory" and doc["scenario_class"].endswith("/factory")
    assert truth.floor is not None and truth.walkers
    assert {o.role for o in truth.objects} >= {ObjectRole.WALL, ObjectRole.SHELF}


def test_a_random_world_comes_from_its_own_stream() -> None:
    drawn = {}
    for seed in range(0, 60):
        spec = random_scenario(seed, world=RANDOM_WORLD)
        drawn[seed] = world_name(spec)
        assert spec == random_scenario(seed, world=drawn[seed])
    assert set(drawn.values()) == set(WORLDS)


def test_an_unknown_world_says_which_there_are() -> None:
    with pytest.raises(ConfigError, match="unknown world 'warehouse'; choose one of: open, room"):
        random_scenario(1000, world="warehouse")
