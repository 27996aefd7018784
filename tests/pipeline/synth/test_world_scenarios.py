"""The named world scenarios: registered, each with its world option, written and read back."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from pipeline.synth import get_scenario, load_truth, write_recording
from pipeline.synth.objects import ObjectRole
from tests.pipeline.synth.worlds import short

WORLDS = {"room", "people", "uneven-floor", "dust", "factory"}


def test_world_scenarios_are_registered_on_set1s_robot() -> None:
    set1 = get_scenario("set1-box")
    for name in WORLDS:
        spec = get_scenario(name)
        assert spec.lidars == set1.lidars and spec.motion == set1.motion
    assert get_scenario("room").scene.room is not None
    assert get_scenario("people").scene.walkers is not None
    assert get_scenario("uneven-floor").scene.floor is not None
    assert get_scenario("dust").scene.dust is not None
    factory = get_scenario("factory").scene
    assert None not in (factory.room, factory.walkers, factory.floor, factory.dust)


def test_a_factory_recording_keeps_its_world_in_the_truth(tmp_path: Path) -> None:
    spec = short("factory", stops=2, dwell_s=0.4)
    expected = write_recording(spec, tmp_path / "out", seed=5, rate_scale=0.02)
    truth = load_truth(tmp_path / "out")
    doc = json.loads((tmp_path / "out" / "truth.json").read_text())
    assert truth.floor is not None and expected.floor is not None
    xy = np.random.default_rng(0).uniform(-3, 3, size=(50, 2))
    np.testing.assert_allclose(truth.floor.height(xy), expected.floor.height(xy))
    assert [w.to_json() for w in truth.walkers] == [w.to_json() for w in expected.walkers]
    assert {obj.role for obj in truth.objects} == {
        ObjectRole.OBJECT,
        ObjectRole.WALL,
        ObjectRole.SHELF,
    }
    assert all("base_on_floor" in stop for stop in doc["stops"])
    for frame, labels in truth.labels.items():
        written = expected.labels[frame]
        np.testing.assert_array_equal(labels.is_moving, written.is_moving)
        np.testing.assert_array_equal(labels.is_spurious, written.is_spurious)
    assert any(labels.is_spurious.any() for labels in truth.labels.values())


def test_a_truth_written_before_the_world_options_still_loads(tmp_path: Path) -> None:
    spec = short("room", stops=2, dwell_s=0.3)
    write_recording(spec, tmp_path / "out", seed=1, rate_scale=0.02)
    path = tmp_path / "out" / "truth.json"
    doc = json.loads(path.read_text())
    for key in ("floor", "walkers"):
        del doc[key]
    for entry in doc["objects"]:
        del entry["role"]
    for keys in doc["labels"]["keys"].values():
        del keys["is_moving"], keys["is_spurious"]
    path.write_text(json.dumps(doc))
    truth = load_truth(tmp_path / "out")
    assert truth.floor is None and truth.walkers == ()
    assert {obj.role for obj in truth.objects} == {ObjectRole.OBJECT}
    for labels in truth.labels.values():
        assert len(labels.is_moving) == len(labels.is_bleeding) and not labels.is_moving.any()
