"""Written recordings follow the input contract; the reader gets back what the truth says."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pipeline.errors import BadInputError
from pipeline.io import read_recording, summarize_recording
from pipeline.io.source import open_recording, stamp_ns
from pipeline.problem import ScanPattern
from pipeline.synth import load_truth, make_world
from pipeline.synth.recording import write_recording
from pipeline.synth.scenarios import get_scenario
from pipeline.transforms import apply, pose_difference

SEED = 11


@pytest.fixture(scope="session")
def tiny_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("synth") / "tiny"
    write_recording("tiny", out, seed=SEED, ros1=True)
    return out


def test_output_layout_and_truth_document(tiny_dir: Path) -> None:
    assert sorted(p.name for p in tiny_dir.iterdir()) == [
        "labels.npz",
        "recording",
        "recording.bag",
        "truth.json",
    ]
    doc = json.loads((tiny_dir / "truth.json").read_text())
    assert doc["schema_version"] == 1 and doc["scenario"] == "tiny" and doc["seed"] == SEED
    assert (doc["base_frame"], doc["odom_frame"], doc["reference_frame"]) == (
        "base_link",
        "odom",
        "lidar_front",
    )
    assert set(doc["lidars"]) == {"lidar_front", "lidar_rear"}
    for frame, lidar in doc["lidars"].items():
        assert lidar["topic"] == f"/{frame}/points" and lidar["model"] == "livox-mid70"
        assert lidar["optical_axis"] == [1.0, 0.0, 0.0]
        for key in ("T_base_lidar_true", "T_base_lidar_initial"):
            assert len(lidar[key]["translation"]) == 3 and len(lidar[key]["rotation_xyzw"]) == 4
        assert (
            lidar["perturbation"]["translation_m"] <= 0.2
            and lidar["perturbation"]["rotation_deg"] <= 5
        )
    assert [stop["index"] for stop in doc["stops"]] == [0, 1, 2, 3]
    assert all(stop["end"] - stop["start"] == pytest.approx(1.3) for stop in doc["stops"])
    assert {obj["kind"] for obj in doc["objects"]} == {"box"}
    assert doc["labels"]["file"] == "labels.npz"
    with np.load(tiny_dir / "labels.npz") as labels:
        assert doc["labels"]["keys"]["lidar_rear"]["is_bleeding"] in labels.files


def test_load_truth_matches_the_world(tiny_dir: Path) -> None:
    truth = load_truth(tiny_dir)
    expected = make_world("tiny", SEED).truth()
    for lidar in expected.lidars:
        loaded = truth.lidar(lidar.frame)
        np.testing.assert_allclose(loaded.T_base_lidar_true, lidar.T_base_lidar_true, atol=1e-12)
        np.testing.assert_allclose(
            loaded.T_base_lidar_initial, lidar.T_base_lidar_initial, atol=1e-12
        )
    for loaded_stop, stop in zip(truth.stops, expected.stops, strict=True):
        np.testing.assert_allclose(
            loaded_stop.T_odom_base_initial, stop.T_odom_base_initial, atol=1e-12
        )
        assert loaded_stop.t_start == stop.t_start
    assert len(truth.objects) == len(expected.objects)
    assert truth.labels["lidar_front"].offsets[-1] == len(truth.labels["lidar_front"].is_bleeding)


@pytest.mark.parametrize("name", ["recording", "recording.bag"])
def test_reader_recovers_frames_extrinsics_stops_and_floor(tiny_dir: Path, name: str) -> None:
    truth = load_truth(tiny_dir)
    problem = read_recording(tiny_dir / name)
    assert problem.frames == ("lidar_front", "lidar_rear")
    assert problem.base_frame == "base_link" and problem.odom_frame == "odom"
    for lidar in problem.lidars:
        # lidar_rear's extrinsic comes through base_link -> mount_rear -> lidar_rear.
        translation, rotation = pose_difference(
            lidar.T_base_lidar, truth.lidar(lidar.frame).T_base_lidar_initial
        )
        assert translation < 1e-6 and rotation < 1e-4
        assert lidar.scan_count == 67
        assert lidar.scan_pattern is ScanPattern.NON_REPETITIVE  # Mid-70s
    assert len(problem.stops) == len(truth.stops)
    for stop, true_stop in zip(problem.stops, truth.stops, strict=True):
        assert true_stop.t_start - 1e-6 <= stop.t_start < stop.t_end <= true_stop.t_end + 1e-6
        translation, rotation = pose_difference(stop.T_odom_base, true_stop.T_odom_base_initial)
        assert translation < 1e-6 and rotation < 1e-4
        for frame, cloud in stop.clouds.items():
            labels = truth.labels_between(stop.t_start, stop.t_end, frame)
            assert len(labels) == len(cloud) > 1000
            T_odom_lidar = true_stop.T_odom_base_true @ truth.lidar(frame).T_base_lidar_true
            floor = (labels.object_index < 0) & ~labels.is_bleeding
            z = apply(T_odom_lidar, cloud[floor])[:, 2]
            assert abs(z.mean()) < 0.003 and z.std() < 0.02


def test_scans_are_published_while_moving_too(tiny_dir: Path) -> None:
    summary = summarize_recording(tiny_dir / "recording", keep_points=False)
    truth = load_truth(tiny_dir)
    for lidar in summary.lidars:
        assert lidar.scans == len(truth.labels[lidar.frame].stamps_ns) == 67
        assert lidar.period_s == pytest.approx(0.1)
        assert 4000 < lidar.points_per_second < 5000  # 5 % of 100k, less the misses
    world = make_world("tiny", SEED)
    stop_scans = sum(len(world.stop_scans(0, j)) for j in range(len(truth.stops)))
    assert stop_scans < 67


def test_spinning_lidars_publish_a_ring_field_and_read_as_repetitive(tmp_path: Path) -> None:
    write_recording("spinning", tmp_path / "spinning", seed=1, rate_scale=0.02)
    summary = summarize_recording(tmp_path / "spinning" / "recording", keep_points=False)
    assert {lidar.scan_pattern for lidar in summary.lidars} == {ScanPattern.REPETITIVE}


def test_same_seed_same_bytes(tiny_dir: Path, tmp_path: Path) -> None:
    again = tmp_path / "again"
    write_recording("tiny", again, seed=SEED)
    for name in ("recording/recording.mcap", "truth.json", "labels.npz"):
        assert (again / name).read_bytes() == (tiny_dir / name).read_bytes(), name


def test_existing_output_directory_is_refused(tiny_dir: Path) -> None:
    with pytest.raises(BadInputError, match="already exists and is not empty; choose a new --out"):
        write_recording("tiny", tiny_dir, seed=SEED)


def test_truth_without_a_recording_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(BadInputError, match="written by `fleetcal synth`"):
        load_truth(tmp_path)


@pytest.mark.parametrize("ros1", [False, True])
def test_header_clock_offsets_move_header_stamps_not_log_times(tmp_path: Path, ros1: bool) -> None:
    offsets = {"/lidar_rear/points": -90 * 86_400 * 10**9, "/odom": 12_345_678}
    spec = get_scenario("tiny").model_copy(update={"header_clock_offset_ns": offsets})
    write_recording(spec, tmp_path / "offset", seed=SEED, ros1=ros1)
    path = tmp_path / "offset" / ("recording.bag" if ros1 else "recording")
    seen: dict[str, set[int]] = {}
    with open_recording(path) as opened:
        for connection, log_ns, raw in opened.messages(opened.connections):
            if connection.topic == "/tf_static":
                continue
            header = opened.deserialize(raw, connection).header
            seen.setdefault(connection.topic, set()).add(stamp_ns(header) - log_ns)
    assert seen == {
        "/lidar_front/points": {0},
        "/lidar_rear/points": {offsets["/lidar_rear/points"]},
        "/odom": {offsets["/odom"]},
    }
    assert (
        json.loads((tmp_path / "offset" / "truth.json").read_text())["spec"][
            "header_clock_offset_ns"
        ]
        == offsets
    )
