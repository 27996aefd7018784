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


NS = 1_000_000_000
WALL_T0 = 1_700_000_000.0


def test_each_stop_has_its_duration_and_each_lidars_scans(tmp_path: Path) -> None:
    spec = Spec(stops=3, points=50, dwell_s=1.2, scan_hz=5.0, t0=WALL_T0)
    truth = write_recording(tmp_path / "r", WriterFormat.ROS2_MCAP, spec)

    stops = inspect_recording(tmp_path / "r")["stops"]

    assert [stop["duration"] for stop in stops] == pytest.approx([1.2, 1.2, 1.2])
    assert [stop["start"] for stop in stops] == pytest.approx([a for a, _ in truth.stop_spans])
    # Scans stamped 0.2 s apart, wholly inside 1.2 s: from 0.2 to 1.0 s into the stop.
    assert [stop["scans"] for stop in stops] == [{"lidar_front": 5, "lidar_rear": 5}] * 3


@pytest.mark.parametrize(("dwell_s", "scans"), [(0.4, 3), (0.8, 7)])
def test_short_and_sparse_stops_are_warnings_not_errors(
    tmp_path: Path, dwell_s: float, scans: int
) -> None:
    spec = Spec(stops=8, points=50, dwell_s=dwell_s, move_s=0.5, t0=WALL_T0)
    write_recording(tmp_path / "r", WriterFormat.ROS2_MCAP, spec)

    document = inspect_recording(tmp_path / "r")

    assert [stop["scans"]["lidar_rear"] for stop in document["stops"]] == [scans] * 8
    short = [w for w in document["warnings"] if w.startswith("short stops")]
    assert short == [
        f"short stops: 8 of 8 stops last under 1 s (shortest: stop 0, {dwell_s:.2f} s); they "
        "are kept, but their clouds hold fewer scans. If the calibration fails its precision "
        "checks, record longer stops"
    ]
    sparse = [w for w in document["warnings"] if w.startswith("sparse stops")]
    if scans < WarningThresholds().min_scans_per_stop:
        assert len(sparse) == 2
        assert sparse[1].startswith(
            "sparse stops: LiDAR lidar_rear (/lidar_rear/points) has fewer than 6 scans in 8 of "
            "8 stops (fewest: 3 in stop 0, scan period 0.100 s)"
        )
    else:
        assert sparse == []


def test_long_stops_are_neither_short_nor_sparse(recordings: dict[str, Path]) -> None:
    warnings = inspect_recording(recordings["bare-mcap"])["warnings"]
    assert not [w for w in warnings if w.startswith(("short stops", "sparse stops"))]


def test_simulated_clock_is_one_clock_and_no_warning(tmp_path: Path) -> None:
    offset = 1000 * NS - round(WALL_T0 * NS)
    spec = Spec(stops=2, points=50, t0=WALL_T0, header_clock_offset_ns=offset)
    write_recording(tmp_path / "r", WriterFormat.ROS2_MCAP, spec)

    document = inspect_recording(tmp_path / "r")

    assert document["trajectory_header_offset"] == pytest.approx(WALL_T0 - 1000)
    assert [lidar["header_offset"] for lidar in document["lidars"]] == pytest.approx(
        [WALL_T0 - 1000] * 2
    )
    assert [lidar["clock_shift"] for lidar in document["lidars"]] == [0, 0]
    assert document["stops"][0]["start"] == pytest.approx(WALL_T0)  # on the log clock
    assert not [w for w in document["warnings"] if "clock" in w]


def test_disagreeing_clocks_are_a_warning(tmp_path: Path) -> None:
    behind = -120 * 86_400 * NS
    offsets = {"/lidar_rear/points": behind}
    spec = Spec(stops=2, points=50, t0=WALL_T0, header_clock_offset_ns=offsets)
    write_recording(tmp_path / "r", WriterFormat.ROS2_MCAP, spec)

    document = inspect_recording(tmp_path / "r")

    assert [lidar["clock_shift"] for lidar in document["lidars"]] == [0, 120 * 86_400]
    assert [stop["scans"] for stop in document["stops"]] == [
        {"lidar_front": 19, "lidar_rear": 19}
    ] * 2
    clocks = [w for w in document["warnings"] if w.startswith("clocks disagree")]
    assert len(clocks) == 1 and "/lidar_rear/points's header stamps are 10368000.000 s" in clocks[0]
