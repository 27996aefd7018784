"""The scenario registry: the paper's sets, non-overlapping fields of view, clear errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.synth.scenarios import get_scenario, scenario_names
from pipeline.synth.simulate import make_world

REQUIRED = {
    "set1-box",
    "set1-cylinder",
    "set1-capsule",
    "set2-box",
    "set2-cylinder",
    "set2-capsule",
    "spinning",
    "driven",
    "floor-only",
    "tiny",
    "room",
    "people",
    "uneven-floor",
    "dust",
    "factory",
}


def test_registry_holds_the_required_scenarios() -> None:
    assert set(scenario_names()) >= REQUIRED
    assert len(get_scenario("set1-box").lidars) == 2
    assert len(get_scenario("set2-capsule").lidars) == 4
    assert get_scenario("set1-box").motion.stops == 16
    assert get_scenario("floor-only").scene.rings == ()
    assert any(lidar.via is not None for lidar in get_scenario("tiny").lidars)


def test_unknown_scenario_lists_the_known_ones() -> None:
    with pytest.raises(ConfigError, match=r"unknown scenario 'nope'.*set1-box.*tiny"):
        get_scenario("nope")


@pytest.mark.parametrize("name", ["set1-box", "set2-box"])
def test_mid70_cones_do_not_overlap(name: str) -> None:
    lidars = get_scenario(name).lidars
    axes = [lidar.T_base_lidar()[:3, :3] @ lidar.model.optical_axis for lidar in lidars]
    for i in range(len(axes)):
        for j in range(i + 1, len(axes)):
            angle = math.degrees(math.acos(np.clip(axes[i] @ axes[j], -1, 1)))
            assert angle > 70.4, (lidars[i].frame, lidars[j].frame, angle)


def test_paper_tilt_of_set1() -> None:
    front = get_scenario("set1-box").lidars[0]
    axis = front.T_base_lidar()[:3, :3] @ front.model.optical_axis
    assert math.degrees(math.asin(-axis[2])) == pytest.approx(35.4)


@pytest.mark.parametrize("name", scenario_names())
def test_every_scenario_builds_its_world(name: str) -> None:
    for seed in range(2):
        world = make_world(name, seed)
        spec = world.spec
        scene = world.scene
        assert scene.model.ngeom == 2 + len(scene.objects) + len(scene.walkers)
        if spec.scene.walkers is None:  # a walkway may leave a ring's sector empty
            assert len(scene.objects) >= sum(ring.count[0] for ring in spec.scene.rings)
        assert world.scan_count(0) == round(
            spec.motion.duration_s / spec.lidars[0].model.scan_period_s
        )
