"""`inspect_recording`: the document `fleetcal inspect --json` prints, and its warnings."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.io.config import ReaderConfig, WarningThresholds
from pipeline.io.errors import NoStopsError
from pipeline.io.inspection import inspect_recording
from pipeline.io.writer import WriterFormat
from tests.pipeline.io.conftest import SCENE
from tests.pipeline.io.recordings import Spec, Truth, write_recording


def test_document_has_the_contract_fields(recordings: dict[str, Path], truth: Truth) -> None:
    document = inspect_recording(recordings["zip"])

    assert document["format"] == "zip" and document["storage"] == "mcap"
    assert document["base_frame"] == "base_link"
    assert [lidar["frame"] for lidar in document["lidars"]] == ["lidar_front", "lidar_rear"]
    front = document["lidars"][0]
    assert front["topic"] == "/lidar_front/points"
    assert front["points"] == 81 * SCENE.points and front["scans"] == 81
    assert front["points_per_second"] == pytest.approx(3000.0)
    assert front["initial_source"] == "tf_static" and len(front["initial"]["rotation_xyzw"]) == 4
    assert len(document["stops"]) == 3
    for stop, (start, end) in zip(document["stops"], truth.stop_spans, strict=True):
        assert start <= stop["start"] < stop["end"] <= end
    assert document["duration"] == pytest.approx(8.0)
    assert document["warnings"] == [
        "too few stops: 3 found, 8 or more recommended (the reference routine has 16); "
        "add stops in different headings"
    ]


def test_enough_stops_no_warning(recordings: dict[str, Path]) -> None:
    config = ReaderConfig(warnings=WarningThresholds(min_stops=3))
    assert inspect_recording(recordings["ros1"], config)["warnings"] == []


def test_missing_tf_is_a_warning_not_an_error(tmp_path: Path) -> None:
    write_recording(
        tmp_path / "r", WriterFormat.ROS2_MCAP, Spec(stops=2, points=50, tf_static=False)
    )

    document = inspect_recording(tmp_path / "r")

    assert [lidar["initial"] for lidar in document["lidars"]] == [None, None]
    missing = [w for w in document["warnings"] if w.startswith("missing tf")]
    assert len(missing) == 2 and "base_link -> lidar_rear" in missing[1]


def test_lidar_that_sees_almost_nothing(tmp_path: Path) -> None:
    spec = Spec(stops=2, points=400, nan_fraction_of={"lidar_rear": 0.9})
    write_recording(tmp_path / "r", WriterFormat.ROS2_MCAP, spec)

    warnings = inspect_recording(tmp_path / "r")["warnings"]

    sparse = [w for w in warnings if "sees almost nothing" in w]
    assert len(sparse) == 1 and sparse[0].startswith("LiDAR lidar_rear (/lidar_rear/points)")


def test_unusable_recording_still_raises(tmp_path: Path) -> None:
    write_recording(tmp_path / "r", WriterFormat.ROS2_MCAP, Spec(stops=2, points=50, dwell_s=0.2))
    with pytest.raises(NoStopsError, match=r"no stops found"):
        inspect_recording(tmp_path / "r")
