"""Exports of a result: each format parsed back with an independent reader (PyYAML, ElementTree,
the `static_transform_publisher` argument grammar) gives the result's transforms within 1e-9."""

from __future__ import annotations

import copy
import math
import shlex
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from pipeline.export import (
    ExportError,
    ExportFormat,
    RecordingCheck,
    calibrated_extrinsics,
    check_recording,
    extrinsics_yaml,
    render,
    tf_static_launch,
    urdf_snippet,
)
from pipeline.io import read_recording
from pipeline.transforms import from_translation_xyzw, from_xyz_rpy

TOLERANCE = 1e-9


def pose(translation: list[float], rotation: Rotation) -> dict[str, list[float]]:
    return {"translation": translation, "rotation_xyzw": rotation.as_quat().tolist()}


def document(**lidars: dict[str, Any]) -> dict[str, Any]:
    return {
        "schema_version": 1,
        "reference_frame": "lidar_front",
        "base_frame": "base_link",
        "lidars": {
            frame: {"topic": f"/{frame}/points", "initial": entry, "calibrated": entry}
            for frame, entry in lidars.items()
        },
        "metric_error": {"initial": 0.08, "final": 0.0021},
        "verdict": {"passed": True, "checks": [{"name": "metric_error", "passed": True}]},
        "pipeline_version": "0.1.0",
        "config_hash": "sha256:" + "0" * 64,
    }


def set1_document() -> dict[str, Any]:
    """The paper's layout: one LiDAR tilted forward, one backward; awkward numbers included."""
    return document(
        lidar_front=pose([0.30000000000000004, 0.0, 0.88], Rotation.from_euler("y", 35.4, True)),
        lidar_rear=pose(
            [-0.29871234567891234, 1.3e-17, 0.8234],
            Rotation.from_euler("xyz", [0.002, 34.4, 180.0 - 1e-7], degrees=True),
        ),
        lidar_left=pose([-1e-05, 0.25, 0.85], Rotation.from_euler("zyx", [90, 30, -0.5], True)),
    )


def expected(doc: dict[str, Any]) -> dict[tuple[str, str], np.ndarray]:
    base = doc["base_frame"]
    return {
        (base, frame): from_translation_xyzw(
            e["calibrated"]["translation"], e["calibrated"]["rotation_xyzw"]
        )
        for frame, e in doc["lidars"].items()
    }


def assert_recording_has(path: Path, doc: dict[str, Any]) -> None:
    """The recording at `path` reads back (`read_recording`) with the result's extrinsics."""
    problem = read_recording(path)
    assert_same(
        {(problem.base_frame, lidar.frame): lidar.T_base_lidar for lidar in problem.lidars}, doc
    )


def assert_same(parsed: dict[tuple[str, str], np.ndarray], doc: dict[str, Any]) -> None:
    want = expected(doc)
    assert sorted(parsed) == sorted(want)
    for edge, T in want.items():
        np.testing.assert_allclose(parsed[edge], T, rtol=0, atol=TOLERANCE, err_msg=str(edge))


# -- independent parsers ----------------------------------------------------------------------


def parse_launch(text: str) -> dict[tuple[str, str], np.ndarray]:
    """What `ros2 launch` hands each node: `args` split like a shell, then the publisher's flags."""
    parsed = {}
    for entry in yaml.safe_load(text)["launch"]:
        node = entry["node"]
        assert (node["pkg"], node["exec"]) == ("tf2_ros", "static_transform_publisher")
        words = shlex.split(node["args"])
        flags = dict(zip(words[::2], words[1::2], strict=True))
        T = from_translation_xyzw(
            [float(flags[f"--{k}"]) for k in "xyz"],
            [float(flags[f"--q{k}"]) for k in "xyzw"],
        )
        parsed[(flags["--frame-id"], flags["--child-frame-id"])] = T
    return parsed


def attribute(element: ET.Element | None, name: str) -> str:
    """`name` of `element`, which must be there (a URDF that lacks it fails the test)."""
    assert element is not None, f"no element for {name}"
    value = element.get(name)
    assert value is not None, f"no attribute {name}"
    return value


def parse_urdf(text: str) -> dict[tuple[str, str], np.ndarray]:
    robot = ET.fromstring(text)
    links = {attribute(link, "name") for link in robot.iter("link")}
    parsed = {}
    for joint in robot.iter("joint"):
        assert joint.get("type") == "fixed"
        parent, child = (
            attribute(joint.find("parent"), "link"),
            attribute(joint.find("child"), "link"),
        )
        assert {parent, child} <= links
        origin = joint.find("origin")
        xyz = [float(v) for v in attribute(origin, "xyz").split()]
        rpy = [float(v) for v in attribute(origin, "rpy").split()]
        parsed[(parent, child)] = from_xyz_rpy(xyz, rpy)
    return parsed


def parse_extrinsics(text: str) -> dict[tuple[str, str], np.ndarray]:
    parsed = {}
    for entry in yaml.safe_load(text)["extrinsics"]:
        values = entry["transform"]
        assert len(values) == 7 and all(isinstance(v, float) for v in values)
        parsed[(entry["parent"], entry["child"])] = from_translation_xyzw(values[:3], values[3:])
    return parsed


def parse_autoware(text: str) -> dict[tuple[str, str], np.ndarray]:
    """Autoware's layout read as its xacro does: xyz and fixed-axis rpy per parent -> child."""
    parsed = {}
    for parent, children in yaml.safe_load(text).items():
        for child, v in children.items():
            assert sorted(v) == sorted(["x", "y", "z", "roll", "pitch", "yaw"])
            T = np.eye(4)
            T[:3, :3] = Rotation.from_euler("xyz", [v["roll"], v["pitch"], v["yaw"]]).as_matrix()
            T[:3, 3] = [v["x"], v["y"], v["z"]]
            parsed[(parent, child)] = T
    return parsed


PARSERS = {
    ExportFormat.TF_STATIC: parse_launch,
    ExportFormat.URDF: parse_urdf,
    ExportFormat.EXTRINSICS: parse_extrinsics,
    ExportFormat.AUTOWARE: parse_autoware,
}


# -- round trips ------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", list(PARSERS))
def test_export_round_trips_to_the_result_transforms(fmt: ExportFormat) -> None:
    doc = set1_document()
    assert_same(PARSERS[fmt](render(doc, fmt, source="robot R1, run 42")), doc)


@settings(max_examples=60, deadline=None)
@given(
    translation=st.lists(st.floats(-50, 50, allow_subnormal=True), min_size=3, max_size=3),
    quat=st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(
        lambda q: sum(v * v for v in q) > 1e-3
    ),
)
def test_every_format_round_trips_any_pose(translation: list[float], quat: list[float]) -> None:
    rotation = Rotation.from_quat(quat)
    # URDF's roll-pitch-yaw cannot say every rotation to 1e-9 at gimbal lock (pitch = +-90 deg),
    # where roll and yaw merge; a mounted LiDAR is never there.
    pitch = abs(math.asin(max(-1.0, min(1.0, -rotation.as_matrix()[2, 0]))))
    doc = document(
        lidar_front=pose([0.1, 0.0, 0.5], Rotation.identity()),
        lidar_other=pose(translation, rotation),
    )
    for fmt, parse in PARSERS.items():
        if fmt in (ExportFormat.URDF, ExportFormat.AUTOWARE) and math.pi / 2 - pitch < 1e-3:
            continue
        assert_same(parse(render(doc, fmt)), doc)


def test_reference_first_then_frames_sorted() -> None:
    doc = set1_document()
    assert [e.child for e in calibrated_extrinsics(doc)] == [
        "lidar_front",
        "lidar_left",
        "lidar_rear",
    ]
    assert [e.is_reference for e in calibrated_extrinsics(doc)] == [True, False, False]


def test_launch_file_names_valid_ros_nodes_and_says_what_it_is() -> None:
    doc = set1_document()
    doc["lidars"]["lidar.top-1"] = doc["lidars"].pop("lidar_left")
    text = tf_static_launch(doc, source="robot R1")
    names = [entry["node"]["name"] for entry in yaml.safe_load(text)["launch"]]
    assert names == [
        "fleetcal_base_link_to_lidar_front",
        "fleetcal_base_link_to_lidar_top_1",
        "fleetcal_base_link_to_lidar_rear",
    ]
    assert text.startswith("# fleetcal calibration, verdict PASSED, metric error 0.0021 m")
    assert "# source: robot R1" in text


def test_urdf_declares_every_link_once() -> None:
    robot = ET.fromstring(urdf_snippet(set1_document()))
    names = [attribute(link, "name") for link in robot.iter("link")]
    assert sorted(names) == ["base_link", "lidar_front", "lidar_left", "lidar_rear"]


def test_extrinsics_yaml_states_each_rotation_also_as_rpy() -> None:
    for entry in yaml.safe_load(extrinsics_yaml(set1_document()))["extrinsics"]:
        from_rpy = Rotation.from_euler("xyz", entry["rpy"])
        from_quat = Rotation.from_quat(entry["transform"][3:])
        assert (from_rpy.inv() * from_quat).magnitude() < TOLERANCE


def test_autoware_yaml_is_keyed_by_the_base_then_each_lidar_frame() -> None:
    parsed = yaml.safe_load(render(set1_document(), "autoware"))
    assert list(parsed) == ["base_link"]
    assert list(parsed["base_link"]) == ["lidar_front", "lidar_left", "lidar_rear"]


def test_autoware_yaml_refuses_a_failed_verdict_unless_allowed() -> None:
    doc = set1_document()
    doc["verdict"]["passed"] = False
    with pytest.raises(ExportError, match="did not pass its verdict"):
        render(doc, ExportFormat.AUTOWARE)
    assert "FAILED (exported anyway)" in render(doc, ExportFormat.AUTOWARE, allow_failed=True)


def test_extrinsics_yaml_carries_the_verdict_and_provenance() -> None:
    data = yaml.safe_load(extrinsics_yaml(set1_document()))
    assert data["passed"] is True
    assert data["metric_error_m"] == 0.0021
    assert data["reference_frame"] == "lidar_front"
    assert data["config_hash"] == "sha256:" + "0" * 64


def test_a_slightly_unnormalised_quaternion_exports_the_same_rotation() -> None:
    doc = set1_document()
    q = doc["lidars"]["lidar_rear"]["calibrated"]["rotation_xyzw"]
    doc["lidars"]["lidar_rear"]["calibrated"]["rotation_xyzw"] = [v * (1 + 4e-7) for v in q]
    for fmt, parse in PARSERS.items():
        assert_same(parse(render(doc, fmt)), doc)


# -- refusals ---------------------------------------------------------------------------------


def test_a_failed_verdict_is_refused_unless_allowed() -> None:
    doc = set1_document()
    doc["verdict"] = {"passed": False, "checks": [{"name": "metric_error", "passed": False}]}
    with pytest.raises(
        ExportError, match=r"did not pass its verdict \(failed checks: metric_error\)"
    ):
        render(doc, ExportFormat.URDF)
    text = render(doc, ExportFormat.TF_STATIC, allow_failed=True)
    assert "verdict FAILED (exported anyway)" in text
    assert_same(parse_launch(text), doc)


def test_an_undetermined_lidar_is_refused() -> None:
    doc = set1_document()
    doc["lidars"]["lidar_left"]["calibrated"] = None
    with pytest.raises(ExportError, match="no calibrated pose for lidar_left"):
        render(doc, ExportFormat.EXTRINSICS, allow_failed=True)


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda d: d.pop("verdict"), "not a fleetcal result document"),
        (lambda d: d.update(lidars={}), "lists no LiDARs"),
        (
            lambda d: d["lidars"]["lidar_rear"]["calibrated"].update(rotation_xyzw=[0, 0, 0, 2]),
            "lidar_rear: the calibrated pose is not a translation",
        ),
        (
            lambda d: d["lidars"]["lidar_rear"]["calibrated"].update(translation=[0, "x", 0]),
            "lidar_rear: the calibrated pose is malformed",
        ),
        (
            lambda d: d["lidars"]["lidar_rear"]["calibrated"].update(translation=[0, math.nan, 0]),
            "lidar_rear: the calibrated pose is not",
        ),
    ],
)
def test_a_damaged_document_is_refused(damage: Any, message: str) -> None:
    doc = copy.deepcopy(set1_document())
    damage(doc)
    with pytest.raises(ExportError, match=message):
        render(doc, ExportFormat.TF_STATIC)


def test_the_recording_is_not_a_text_export() -> None:
    with pytest.raises(ExportError, match="not a text export"):
        render(set1_document(), "recording")


# -- the recording a calibration is written into ------------------------------------------------

RECORDED = {"/lidar_front/points": "lidar_front", "/lidar_rear/points": "lidar_rear"}


def two_lidars() -> dict[str, Any]:
    doc = set1_document()
    del doc["lidars"]["lidar_left"]
    return doc


def test_the_recording_calibrated_matches() -> None:
    check = check_recording(two_lidars(), RECORDED, sha256="ab" * 32, calibrated_sha256="AB" * 32)
    assert check == RecordingCheck(mismatches=(), notes=())


@pytest.mark.parametrize(
    ("recorded", "sha256", "mismatch"),
    [
        (
            {"/lidar_front/points": "lidar_front"},
            None,
            "it has no LiDAR lidar_rear (its LiDARs: lidar_front on /lidar_front/points)",
        ),
        (
            {"/lidar_front/points": "lidar_front", "/points": "lidar_rear"},
            None,
            "its lidar_rear is on /points, the result's on /lidar_rear/points",
        ),
        (RECORDED, "cd" * 32, f"its SHA-256 is {'cd' * 32}, the calibrated upload's {'ab' * 32}"),
    ],
)
def test_another_recording_is_a_mismatch(
    recorded: dict[str, str], sha256: str | None, mismatch: str
) -> None:
    check = check_recording(two_lidars(), recorded, sha256=sha256, calibrated_sha256="ab" * 32)
    assert mismatch in check.mismatches


def test_what_the_copy_leaves_as_recorded_is_noted() -> None:
    recorded = {**RECORDED, "/lidar_top/points": "lidar_top"}
    check = check_recording(two_lidars(), recorded, sha256=None, calibrated_sha256="ab" * 32)
    assert check.mismatches == ()
    assert check.notes == (
        f"its SHA-256 was not compared with the calibrated upload's ({'ab' * 32}): it is a bag "
        "directory, not the file uploaded; its LiDARs were",
        "lidar_top: not in the result, kept with the recorded extrinsics",
    )
