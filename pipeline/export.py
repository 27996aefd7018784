"""A calibration result in the robot's configuration: `result.json` -> ROS 2 launch YAML of
`static_transform_publisher` nodes, a URDF snippet of fixed joints, `extrinsics.yaml`, or
Autoware's `sensor_kit_calibration.yaml` layout.

Pure functions of the result document (DESIGN.md's output contract). Numbers are written with
`repr`, the shortest text that reads back to the same float64, so every export round-trips.
"""

from __future__ import annotations

import enum
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from pipeline.errors import BadInputError

if TYPE_CHECKING:
    from pipeline.transforms import Matrix4

# A result's quaternions are unit to ~1e-12; one further off is a damaged document.
_UNIT_TOLERANCE = 1e-6


class ExportError(BadInputError):
    """The result cannot be exported (failed verdict, undetermined LiDAR, damaged document)."""


class ExportFormat(enum.StrEnum):
    TF_STATIC = "tf-static"
    URDF = "urdf"
    EXTRINSICS = "extrinsics"
    AUTOWARE = "autoware"
    RECORDING = "recording"


class MapFormat(enum.StrEnum):
    """Point-cloud files of the accumulated map (`pipeline.map_export`, `fleetcal export-map`)."""

    PLY = "ply"
    PCD = "pcd"


TEXT_FORMATS: tuple[ExportFormat, ...] = (
    ExportFormat.TF_STATIC,
    ExportFormat.URDF,
    ExportFormat.EXTRINSICS,
    ExportFormat.AUTOWARE,
)
FILE_NAMES: Mapping[ExportFormat, str] = {
    ExportFormat.TF_STATIC: "tf_static.launch.yaml",
    ExportFormat.URDF: "lidars.urdf",
    ExportFormat.EXTRINSICS: "extrinsics.yaml",
    ExportFormat.AUTOWARE: "sensor_kit_calibration.yaml",
    ExportFormat.RECORDING: "calibrated.mcap",
}
MEDIA_TYPES: Mapping[ExportFormat, str] = {
    ExportFormat.TF_STATIC: "application/yaml",
    ExportFormat.URDF: "application/xml",
    ExportFormat.EXTRINSICS: "application/yaml",
    ExportFormat.AUTOWARE: "application/yaml",
    ExportFormat.RECORDING: "application/octet-stream",
}


@dataclass(frozen=True)
class Extrinsic:
    """One calibrated edge `T_parent_child`: translation (m) and unit quaternion `[x, y, z, w]`."""

    parent: str
    child: str
    translation: tuple[float, float, float]
    rotation_xyzw: tuple[float, float, float, float]
    is_reference: bool = False

    def matrix(self) -> Matrix4:
        """(4, 4) `T_parent_child`."""
        # scipy (through pipeline.transforms) only here: `fleetcal --help` imports this module.
        from pipeline.transforms import from_translation_xyzw

        return from_translation_xyzw(self.translation, self.rotation_xyzw)

    @property
    def rpy(self) -> tuple[float, float, float]:
        """Fixed-axis roll, pitch, yaw in radians (URDF's `rpy`)."""
        from scipy.spatial.transform import Rotation

        roll, pitch, yaw = Rotation.from_quat(self.rotation_xyzw).as_euler("xyz")
        return float(roll), float(pitch), float(yaw)


def calibrated_extrinsics(
    document: Mapping[str, Any], *, allow_failed: bool = False
) -> tuple[Extrinsic, ...]:
    """The calibrated `T_base_lidar` of every LiDAR, the reference first, then by frame.

    Raises `ExportError` when the verdict failed (unless `allow_failed`), when a LiDAR has no
    calibrated pose (the data could not determine it), or when the document is malformed.
    """
    try:
        lidars: Mapping[str, Any] = document["lidars"]
        base = str(document.get("base_frame") or "base_link")
        reference = str(document.get("reference_frame") or "")
        passed = bool(document["verdict"]["passed"])
    except (KeyError, TypeError) as err:
        raise ExportError(
            f"this is not a fleetcal result document (missing {err}); pass a result.json or a run "
            "that has finished"
        ) from None
    if not isinstance(lidars, Mapping) or not lidars:
        raise ExportError("the result lists no LiDARs; there is nothing to export")
    if not passed and not allow_failed:
        failed = [
            str(check.get("name"))
            for check in document["verdict"].get("checks", [])
            if isinstance(check, Mapping) and not check.get("passed", True)
        ]
        raise ExportError(
            "the calibration did not pass its verdict"
            + (f" (failed checks: {', '.join(failed)})" if failed else "")
            + "; fix the recording and calibrate again, or export anyway with allow-failed"
        )
    undetermined = sorted(
        frame
        for frame, entry in lidars.items()
        if not isinstance(entry, Mapping) or not entry.get("calibrated")
    )
    if undetermined:
        raise ExportError(
            f"no calibrated pose for {', '.join(undetermined)}: the data could not determine it "
            "(see the run's failed checks); record objects around the robot and calibrate again"
        )
    order = sorted(lidars, key=lambda frame: (frame != reference, frame))
    return tuple(_extrinsic(base, frame, lidars[frame], frame == reference) for frame in order)


def _extrinsic(base: str, frame: str, entry: Mapping[str, Any], is_reference: bool) -> Extrinsic:
    # numpy and xml.sax here, not at the top: `fleetcal --help` imports this module for its enums.
    import numpy as np

    pose = entry["calibrated"]
    try:
        translation = tuple(float(v) for v in pose["translation"])
        quat = np.asarray([float(v) for v in pose["rotation_xyzw"]], dtype=np.float64)
    except (KeyError, TypeError, ValueError) as err:
        raise ExportError(f"{frame}: the calibrated pose is malformed ({err})") from None
    norm = float(np.linalg.norm(quat)) if quat.shape == (4,) else math.nan
    if (
        len(translation) != 3
        or not all(math.isfinite(v) for v in translation)
        or not math.isfinite(norm)
        or abs(norm - 1.0) > _UNIT_TOLERANCE
    ):
        raise ExportError(
            f"{frame}: the calibrated pose is not a translation [x, y, z] and a unit quaternion "
            f"[x, y, z, w] ({dict(pose)}); the result document is damaged"
        )
    q = quat / norm
    return Extrinsic(
        parent=base,
        child=frame,
        translation=(translation[0], translation[1], translation[2]),
        rotation_xyzw=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
        is_reference=is_reference,
    )


@dataclass(frozen=True)
class RecordingCheck:
    """How a recording compares with the result about to be written into it. `mismatches`: why
    it is not the recording the result calibrated (refuse unless told otherwise); `notes`: what
    the user should know all the same."""

    mismatches: tuple[str, ...]
    notes: tuple[str, ...]


def check_recording(
    document: Mapping[str, Any],
    lidar_frames: Mapping[str, str],
    *,
    sha256: str | None = None,
    calibrated_sha256: str | None = None,
) -> RecordingCheck:
    """Compare a recording's LiDARs (`lidar_frames`: `{topic: frame}`) and, where both are known,
    its SHA-256 with those of the recording `document` calibrated (`calibrated_sha256`: a run's
    upload). Every LiDAR of the result must be in the recording, on the same topic."""
    lidars: Mapping[str, Any] = document.get("lidars") or {}
    recorded = {frame: topic for topic, frame in lidar_frames.items()}
    listing = ", ".join(f"{frame} on {topic}" for frame, topic in sorted(recorded.items()))
    mismatches, notes = [], []
    missing = sorted(frame for frame in lidars if frame not in recorded)
    if missing:
        mismatches.append(f"it has no LiDAR {', '.join(missing)} (its LiDARs: {listing or 'none'})")
    for frame, entry in sorted(lidars.items()):
        topic = entry.get("topic") if isinstance(entry, Mapping) else None
        if frame in recorded and topic and topic != recorded[frame]:
            mismatches.append(f"its {frame} is on {recorded[frame]}, the result's on {topic}")
    if calibrated_sha256 and sha256 and sha256.lower() != calibrated_sha256.lower():
        mismatches.append(
            f"its SHA-256 is {sha256}, the calibrated upload's {calibrated_sha256.lower()}"
        )
    elif calibrated_sha256 and not sha256:
        notes.append(
            f"its SHA-256 was not compared with the calibrated upload's ({calibrated_sha256}): "
            "it is a bag directory, not the file uploaded; its LiDARs were"
        )
    extra = sorted(frame for frame in recorded if frame not in lidars)
    if extra:
        notes.append(f"{', '.join(extra)}: not in the result, kept with the recorded extrinsics")
    return RecordingCheck(tuple(mismatches), tuple(notes))


# -- formats ---------------------------------------------------------------------------------------


def tf_static_launch(
    document: Mapping[str, Any], *, allow_failed: bool = False, source: str | None = None
) -> str:
    """A ROS 2 launch file (YAML) with one `tf2_ros static_transform_publisher` node per LiDAR.

    Start it with `ros2 launch ./tf_static.launch.yaml`; each node publishes `base -> lidar` on
    `/tf_static` from its `--x --y --z --qx --qy --qz --qw --frame-id --child-frame-id` arguments.
    """
    extrinsics = calibrated_extrinsics(document, allow_failed=allow_failed)
    lines = [*_header(document, source, "#"), "launch:"]
    for edge in extrinsics:
        x, y, z = edge.translation
        qx, qy, qz, qw = edge.rotation_xyzw
        args = (
            f"--x {_num(x)} --y {_num(y)} --z {_num(z)} "
            f"--qx {_num(qx)} --qy {_num(qy)} --qz {_num(qz)} --qw {_num(qw)} "
            f"--frame-id {edge.parent} --child-frame-id {edge.child}"
        )
        lines += [
            "  - node:",
            "      pkg: tf2_ros",
            "      exec: static_transform_publisher",
            f"      name: {json.dumps(_ros_name(f'fleetcal_{edge.parent}_to_{edge.child}'))}",
            f"      args: {json.dumps(args)}",
        ]
    return "\n".join(lines) + "\n"


def urdf_snippet(
    document: Mapping[str, Any], *, allow_failed: bool = False, source: str | None = None
) -> str:
    """A URDF `<robot>` with the base link, a link per LiDAR and a fixed joint base -> LiDAR.

    Valid by itself (check_urdf); to merge into a robot description, copy the LiDAR links and
    joints (the base link is declared only so the snippet stands alone).
    """
    from xml.sax.saxutils import quoteattr

    extrinsics = calibrated_extrinsics(document, allow_failed=allow_failed)
    base = extrinsics[0].parent
    lines = ['<?xml version="1.0"?>']
    lines += [
        f"<!-- {_xml_comment(line.lstrip('# '))} -->" for line in _header(document, source, "#")
    ]
    lines += ['<robot name="fleetcal_lidars">', f"  <link name={quoteattr(base)}/>"]
    for edge in extrinsics:
        xyz = " ".join(_num(v) for v in edge.translation)
        rpy = " ".join(_num(v) for v in edge.rpy)
        lines += [
            f"  <link name={quoteattr(edge.child)}/>",
            f'  <joint name={quoteattr(f"{edge.parent}_to_{edge.child}")} type="fixed">',
            f"    <parent link={quoteattr(edge.parent)}/>",
            f"    <child link={quoteattr(edge.child)}/>",
            f"    <origin xyz={quoteattr(xyz)} rpy={quoteattr(rpy)}/>",
            "  </joint>",
        ]
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def extrinsics_yaml(
    document: Mapping[str, Any], *, allow_failed: bool = False, source: str | None = None
) -> str:
    """`extrinsics.yaml`: per LiDAR its parent, child, `[x, y, z, qx, qy, qz, qw]` and beside the
    quaternion the same rotation as fixed-axis `rpy` in radians (URDF's convention)."""
    extrinsics = calibrated_extrinsics(document, allow_failed=allow_failed)
    metric = document.get("metric_error") or {}
    lines = [
        *_header(document, source, "#"),
        "# transform: T_parent_child (maps child points into parent) as "
        "[x, y, z, qx, qy, qz, qw], metres and a unit quaternion",
        "# rpy: the same rotation as fixed-axis roll, pitch, yaw (x, then y, then z) in radians",
        f"reference_frame: {json.dumps(str(document.get('reference_frame', '')))}",
        f"passed: {'true' if document['verdict']['passed'] else 'false'}",
        f"metric_error_m: {_num(metric.get('final'))}",
        f"pipeline_version: {json.dumps(str(document.get('pipeline_version', '')))}",
        f"config_hash: {json.dumps(str(document.get('config_hash', '')))}",
        "extrinsics:",
    ]
    for edge in extrinsics:
        values = ", ".join(_num(v) for v in (*edge.translation, *edge.rotation_xyzw))
        lines += [
            f"  - parent: {json.dumps(edge.parent)}",
            f"    child: {json.dumps(edge.child)}",
            f"    transform: [{values}]",
            f"    rpy: [{', '.join(_num(v) for v in edge.rpy)}]",
        ]
    return "\n".join(lines) + "\n"


def autoware_yaml(
    document: Mapping[str, Any], *, allow_failed: bool = False, source: str | None = None
) -> str:
    """Autoware's `sensor_kit_calibration.yaml` / `sensors_calibration.yaml` layout:
    `parent: {child: {x, y, z, roll, pitch, yaw}}`, metres and fixed-axis radians, which
    Autoware's sensor kit xacro turns into each joint's `<origin xyz rpy>`."""
    extrinsics = calibrated_extrinsics(document, allow_failed=allow_failed)
    lines = [*_header(document, source, "#"), f"{json.dumps(extrinsics[0].parent)}:"]
    for edge in extrinsics:
        lines.append(f"  {json.dumps(edge.child)}:")
        values = (*edge.translation, *edge.rpy)
        lines += [
            f"    {name}: {_num(value)}"
            for name, value in zip(("x", "y", "z", "roll", "pitch", "yaw"), values, strict=True)
        ]
    return "\n".join(lines) + "\n"


def render(
    document: Mapping[str, Any],
    fmt: ExportFormat | str,
    *,
    allow_failed: bool = False,
    source: str | None = None,
) -> str:
    """The text export `fmt` (`tf-static`, `urdf`, `extrinsics` or `autoware`) of `document`."""
    fmt = ExportFormat(fmt)
    if fmt is ExportFormat.TF_STATIC:
        return tf_static_launch(document, allow_failed=allow_failed, source=source)
    if fmt is ExportFormat.URDF:
        return urdf_snippet(document, allow_failed=allow_failed, source=source)
    if fmt is ExportFormat.EXTRINSICS:
        return extrinsics_yaml(document, allow_failed=allow_failed, source=source)
    if fmt is ExportFormat.AUTOWARE:
        return autoware_yaml(document, allow_failed=allow_failed, source=source)
    raise ExportError(f"{fmt.value} is not a text export; use pipeline.io.retag for recordings")


# -- helpers ---------------------------------------------------------------------------------------


def _num(value: Any) -> str:
    """`repr` of a float (exact round trip), spelled so YAML 1.1 and 1.2 both read a float."""
    if value is None:
        return "null"
    number = float(value)
    if not math.isfinite(number):
        return ".nan" if math.isnan(number) else (".inf" if number > 0 else "-.inf")
    text = repr(number)
    mantissa, _, exponent = text.partition("e")
    if exponent and "." not in mantissa:
        text = f"{mantissa}.0e{exponent}"
    return text


def _ros_name(text: str) -> str:
    """A valid ROS node name: letters, digits and underscores, not starting with a digit."""
    cleaned = "".join(c if c.isalnum() and c.isascii() else "_" for c in text)
    return cleaned if cleaned[:1].isalpha() else f"n_{cleaned}"


def _xml_comment(text: str) -> str:
    return text.replace("--", "- -")


def _header(document: Mapping[str, Any], source: str | None, mark: str) -> list[str]:
    verdict = "PASSED" if document["verdict"]["passed"] else "FAILED (exported anyway)"
    metric = (document.get("metric_error") or {}).get("final")
    lines = [
        f"{mark} fleetcal calibration, verdict {verdict}"
        + (f", metric error {float(metric):.4g} m" if metric is not None else ""),
        f"{mark} pipeline {document.get('pipeline_version', '?')}, config "
        f"{document.get('config_hash', '?')}",
    ]
    if source:
        lines.append(f"{mark} source: {source}")
    return lines
