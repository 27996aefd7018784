"""The map before and after calibration as PLY and PCD, read back with hand-written parsers of
both formats (headers and binary bodies by numpy, not open3d): points where the poses put them,
one colour per LiDAR."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from pipeline.export import ExportError
from pipeline.io import read_recording
from pipeline.io.writer import WriterFormat
from pipeline.map_export import maps_before_after, write_map
from pipeline.problem import CalibrationProblem
from pipeline.report import LIDAR_COLOURS
from pipeline.result import pose_document
from pipeline.transforms import from_xyz_rpy, invert
from tests.pipeline.io.recordings import Spec, write_recording
from workers.cli import app

SHIFT = from_xyz_rpy([0.05, -0.02, 0.01], [0.0, 0.0, 0.03])


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp("map") / "rec"
    write_recording(bag, WriterFormat.ROS2_MCAP, Spec(stops=2, points=200))
    return bag


@pytest.fixture(scope="module")
def problem(recording: Path) -> CalibrationProblem:
    return read_recording(recording)


def result_for(problem: CalibrationProblem) -> dict[str, Any]:
    """A result whose stops are the odometry's and whose second LiDAR moved by `SHIFT`."""
    frames = problem.frames
    lidars = {}
    for i, frame in enumerate(frames):
        T = problem.lidar(frame).T_base_lidar
        calibrated = T @ SHIFT if i == 1 else T
        lidars[frame] = {"initial": pose_document(T), "calibrated": pose_document(calibrated)}
    return {
        "reference_frame": frames[0],
        "base_frame": problem.base_frame,
        "lidars": lidars,
        "verdict": {"passed": True, "checks": []},
        "stops": [
            {"index": s.index, "T_odom_base": pose_document(s.T_odom_base)} for s in problem.stops
        ],
    }


def expected_points(
    problem: CalibrationProblem, frame: str, T_base_lidar: np.ndarray
) -> np.ndarray:
    T_W_odom = invert(problem.stops[0].T_odom_base)
    return np.concatenate(
        [
            s.clouds[frame] @ (T_W_odom @ s.T_odom_base @ T_base_lidar)[:3, :3].T
            + (T_W_odom @ s.T_odom_base @ T_base_lidar)[:3, 3]
            for s in problem.stops
        ]
    )


# -- independent readers ----------------------------------------------------------------------

_NUMPY = {"float": "f4", "double": "f8", "uchar": "u1", "uint8": "u1", "float32": "f4",
          "float64": "f8"}  # fmt: skip


def read_ply(path: Path) -> tuple[np.ndarray, np.ndarray]:
    data = path.read_bytes()
    head, _, body = data.partition(b"end_header\n")
    lines = head.decode("ascii").splitlines()
    assert lines[0] == "ply" and lines[1] == "format binary_little_endian 1.0"
    count = next(int(line.split()[2]) for line in lines if line.startswith("element vertex"))
    props = [line.split()[1:] for line in lines if line.startswith("property")]
    dtype = np.dtype([(name, "<" + _NUMPY[kind]) for kind, name in props])
    rows = np.frombuffer(body[: count * dtype.itemsize], dtype=dtype)
    xyz = np.stack([rows[k].astype(np.float64) for k in "xyz"], axis=1)
    rgb = np.stack([rows[k] for k in ("red", "green", "blue")], axis=1).astype(np.float64) / 255
    return xyz, rgb


def read_pcd(path: Path) -> tuple[np.ndarray, np.ndarray]:
    data = path.read_bytes()
    fields: dict[str, list[str]] = {}
    offset = 0
    for line in data.split(b"\n"):
        offset += len(line) + 1
        key, *values = line.decode("ascii").split()
        fields[key] = values
        if key == "DATA":
            break
    assert fields["DATA"] == ["binary"]
    kinds = {("F", "4"): "f4", ("F", "8"): "f8", ("U", "4"): "u4", ("I", "4"): "i4"}
    dtype = np.dtype(
        [
            (n, "<" + kinds[(t, s)])
            for n, t, s in zip(fields["FIELDS"], fields["TYPE"], fields["SIZE"], strict=True)
        ]
    )
    rows = np.frombuffer(
        data[offset : offset + int(fields["POINTS"][0]) * dtype.itemsize], dtype=dtype
    )
    xyz = np.stack([rows[k].astype(np.float64) for k in "xyz"], axis=1)
    packed = rows["rgb"].view("<u4") if rows["rgb"].dtype != np.uint32 else rows["rgb"]
    rgb = np.stack([(packed >> 16) & 255, (packed >> 8) & 255, packed & 255], axis=1) / 255
    return xyz, rgb.astype(np.float64)


# -- tests ------------------------------------------------------------------------------------


def test_before_uses_the_initial_and_after_the_calibrated_extrinsics(
    problem: CalibrationProblem,
) -> None:
    before, after = maps_before_after(problem, result_for(problem))
    assert before.frames == after.frames == problem.frames
    for i, frame in enumerate(problem.frames):
        T = problem.lidar(frame).T_base_lidar
        np.testing.assert_allclose(
            before.points[before.lidar == i], expected_points(problem, frame, T), atol=1e-9
        )
        T_after = T @ SHIFT if i == 1 else T
        np.testing.assert_allclose(
            after.points[after.lidar == i], expected_points(problem, frame, T_after), atol=1e-9
        )


@pytest.mark.parametrize("reader", [read_ply, read_pcd], ids=["ply", "pcd"])
def test_the_file_reads_back_with_a_colour_per_lidar(
    problem: CalibrationProblem, tmp_path: Path, reader: Any
) -> None:
    _, after = maps_before_after(problem, result_for(problem))
    fmt = reader.__name__.removeprefix("read_")
    path = write_map(tmp_path / f"map.{fmt}", after, fmt)
    xyz, rgb = reader(path)
    np.testing.assert_allclose(xyz, after.points, atol=1e-4)  # PCD stores float32
    palette = np.array([[int(c[k : k + 2], 16) / 255 for k in (1, 3, 5)] for c in LIDAR_COLOURS])
    np.testing.assert_allclose(rgb, palette[after.lidar], atol=1 / 255)
    assert len({tuple(c) for c in rgb}) == len(problem.frames)


def test_a_result_of_another_recording_is_refused(problem: CalibrationProblem) -> None:
    document = result_for(problem)
    document["stops"] = document["stops"][:1]
    with pytest.raises(ExportError, match="1 refined stop poses but the recording 2 stops"):
        maps_before_after(problem, document)
    document = result_for(problem)
    document["lidars"]["lidar_elsewhere"] = document["lidars"][problem.frames[0]]
    with pytest.raises(ExportError, match="no LiDAR lidar_elsewhere"):
        maps_before_after(problem, document)


def test_an_existing_file_is_not_overwritten(problem: CalibrationProblem, tmp_path: Path) -> None:
    before, _ = maps_before_after(problem, result_for(problem))
    (tmp_path / "map.ply").write_text("keep me")
    with pytest.raises(ExportError, match="already exists"):
        write_map(tmp_path / "map.ply", before, "ply")


def test_the_command_writes_both_maps(
    problem: CalibrationProblem, recording: Path, tmp_path: Path
) -> None:
    import json

    result = tmp_path / "result.json"
    result.write_text(json.dumps(result_for(problem)))
    ran = CliRunner().invoke(
        app,
        [
            "export-map",
            str(result),
            "--recording",
            str(recording),
            "--format",
            "pcd",
            "--out",
            str(tmp_path / "maps"),
        ],
    )
    assert ran.exit_code == 0, ran.output
    before, _ = read_pcd(tmp_path / "maps" / "map_before.pcd")
    after, _ = read_pcd(tmp_path / "maps" / "map_after.pcd")
    assert before.shape == after.shape and not np.allclose(before, after)
