"""Property-based fuzzing of the recording reader: a small valid recording of each format, with
bytes overwritten, zeroed or cut off at random, either reads into a problem or raises a
`PipelineError` (whose message names the file); nothing else escapes the reader."""

from __future__ import annotations

import io
import shutil
import sqlite3
import struct
import tarfile
import zipfile
from collections.abc import Callable
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.errors import PipelineError
from pipeline.io import read_recording
from pipeline.io.errors import CorruptRecordingError
from pipeline.io.writer import WriterFormat
from tests.pipeline.io.recordings import T_BASE_MOUNT, Spec, write_recording

# Small but complete: two LiDARs, odometry, tf_static and two stops, about 90 KB per format.
SPEC = Spec(stops=2, points=40, dwell_s=1.2, move_s=0.5, odom_hz=20, scan_hz=5)


def _archive(directory: Path, kind: str) -> bytes:
    buffer = io.BytesIO()
    if kind == "zip":
        with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
            for file in sorted(directory.rglob("*")):
                archive.write(file, Path(directory.name) / file.relative_to(directory))
    else:
        with tarfile.open(fileobj=buffer, mode="w:gz") as archive:
            archive.add(directory, arcname=directory.name)
    return buffer.getvalue()


@pytest.fixture(scope="module")
def originals(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """Each format's bytes as a robot would upload them (a bag directory as an archive)."""
    root = tmp_path_factory.mktemp("fuzz-originals")
    mcap, sqlite, ros1 = root / "mcap", root / "sqlite", root / "r.bag"
    write_recording(mcap, WriterFormat.ROS2_MCAP, SPEC)
    write_recording(sqlite, WriterFormat.ROS2_SQLITE3, SPEC)
    write_recording(ros1, WriterFormat.ROS1, SPEC)
    found = {
        "mcap": (mcap / "mcap.mcap").read_bytes(),
        "db3": (sqlite / "sqlite.db3").read_bytes(),
        "bag": ros1.read_bytes(),
        "zip": _archive(mcap, "zip"),
        "tar.gz": _archive(mcap, "tar.gz"),
    }
    for name, data in found.items():
        path = root / f"check.{name}"
        path.write_bytes(data)
        assert len(read_recording(path).stops) == 2, f"the unmutated {name} must read"
    shutil.rmtree(root)
    return found


@st.composite
def mutations(draw: st.DrawFn, size: int) -> tuple[list[tuple[int, bytes]], int | None]:
    """Overwrites (position, bytes) and an optional cut-off length."""
    where = st.integers(0, size - 1)
    patches = draw(
        st.lists(
            st.tuples(
                where,
                st.one_of(
                    st.binary(min_size=1, max_size=4),
                    st.sampled_from([b"\xff\xff\xff\xff", b"\x00" * 8, b"\x7f\xff\xff\xff"]),
                    st.integers(1, 512).map(lambda n: b"\x00" * n),
                ),
            ),
            min_size=0,
            max_size=8,
        )
    )
    cut = draw(st.one_of(st.none(), where))
    return patches, cut


def mutate(data: bytes, patches: list[tuple[int, bytes]], cut: int | None) -> bytes:
    buffer = bytearray(data)
    for position, patch in patches:
        buffer[position : position + len(patch)] = patch[: len(buffer) - position]
    return bytes(buffer[:cut] if cut is not None else buffer)


@pytest.mark.parametrize("name", ["mcap", "db3", "bag", "zip", "tar.gz"])
def test_mutated_recordings_read_or_raise_a_pipeline_error(
    originals: dict[str, bytes], name: str, tmp_path_factory: pytest.TempPathFactory
) -> None:
    original = originals[name]
    scratch = tmp_path_factory.mktemp(f"fuzz-{name}")

    @settings(
        max_examples=60,
        deadline=None,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )
    @given(change=mutations(len(original)))
    def check(change: tuple[list[tuple[int, bytes]], int | None]) -> None:
        path = scratch / f"upload.{name}"
        path.write_bytes(mutate(original, *change))
        try:
            read_recording(path)
        except PipelineError as err:
            assert str(err), "every error says what is wrong"

    check()


# -- what the fuzzer found, pinned -------------------------------------------------------------


def _damage_mcap_topic(data: bytes) -> bytes:
    """A topic name that is not UTF-8 (rosbags' decode raised UnicodeDecodeError)."""
    at = data.rindex(b"/lidar_front/points")  # the summary section, which rosbags reads
    return data[:at] + b"\xff" + data[at + 1 :]


def _damage_mcap_length(size: int) -> Callable[[bytes], bytes]:
    """The first record's uint64 length after the magic and opcode, set to `size` (rosbags asked
    Python for that many bytes: MemoryError, or OverflowError past ssize_t)."""

    def damage(data: bytes) -> bytes:
        at = len(b"\x89MCAP0\r\n") + 1
        return data[:at] + size.to_bytes(8, "little") + data[at + 8 :]

    return damage


def _damage_ros1_time(data: bytes) -> bytes:
    """A message record whose header time differs from its index entry (a rosbags assert)."""
    field = b"\x0d\x00\x00\x00time="
    at = data.index(field) + len(field)
    return data[:at] + b"\x01\x02\x03\x04\x05\x06\x07\x08" + data[at + 8 :]


def _damage_ros1_header_op(data: bytes) -> bytes:
    """The bag header record's op code set to 0, no record type: rosbags' own error message then
    failed in the standard library (ValueError from the enum lookup)."""
    at = data.index(b"op=\x03") + len(b"op=")
    return data[:at] + b"\x00" + data[at + 1 :]


def _damage_tf_static(value: float, offset: int) -> Callable[[bytes], bytes]:
    """The float64 `offset` places after the start of the base_link -> rear_mount translation in
    /tf_static (x, y, z, then the quaternion's x, y, z, w) set to `value`. The fuzzer found a
    quaternion component of 2.7e154: its norm overflows, and the reader raised a bare ValueError."""

    def damage(data: bytes) -> bytes:
        at = data.index(struct.pack("<3d", *T_BASE_MOUNT[:3, 3])) + 8 * offset
        return data[:at] + struct.pack("<d", value) + data[at + 8 :]

    return damage


def _null_sqlite_topic(path: Path) -> None:
    """A topic row whose name is NULL (the sort of connections by topic raised TypeError)."""
    connection = sqlite3.connect(path)
    try:
        connection.execute("PRAGMA writable_schema = ON")
        connection.execute(
            "UPDATE sqlite_master SET sql = replace(sql, 'name TEXT NOT NULL', 'name TEXT') "
            "WHERE name = 'topics'"
        )
        connection.commit()
    finally:
        connection.close()
    connection = sqlite3.connect(path)
    try:
        connection.execute("UPDATE topics SET name = NULL WHERE id = 1")
        connection.commit()
    finally:
        connection.close()


@pytest.mark.parametrize(
    ("name", "damage"),
    [
        ("mcap", _damage_mcap_topic),
        ("mcap", _damage_mcap_length(2**50)),
        ("mcap", _damage_mcap_length(2**64 - 1)),
        ("bag", _damage_ros1_time),
        ("bag", _damage_ros1_header_op),
    ],
    ids=[
        "mcap-topic-not-utf8",
        "mcap-length-absurd",
        "mcap-length-past-ssize_t",
        "ros1-time",
        "ros1-header-op",
    ],
)
def test_damage_the_fuzzer_found_is_a_corrupt_recording(
    originals: dict[str, bytes], name: str, damage: Callable[[bytes], bytes], tmp_path: Path
) -> None:
    path = tmp_path / f"upload.{name}"
    path.write_bytes(damage(originals[name]))
    with pytest.raises(CorruptRecordingError, match="truncated or damaged"):
        read_recording(path)


@pytest.mark.parametrize("name", ["mcap", "bag"])
@pytest.mark.parametrize(
    ("damage", "says"),
    [
        (_damage_tf_static(2.6815624260044027e154, 3), "has no direction"),
        (_damage_tf_static(float("nan"), 0), "is not finite"),
    ],
    ids=["quaternion-overflows", "translation-nan"],
)
def test_a_tf_static_edge_that_is_no_transform_is_a_corrupt_recording(
    originals: dict[str, bytes],
    name: str,
    damage: Callable[[bytes], bytes],
    says: str,
    tmp_path: Path,
) -> None:
    path = tmp_path / f"upload.{name}"
    path.write_bytes(damage(originals[name]))
    with pytest.raises(CorruptRecordingError) as raised:
        read_recording(path)
    message = str(raised.value)
    assert str(path) in message and "base_link -> rear_mount" in message and says in message


def test_a_sqlite3_topic_without_a_name_is_a_corrupt_recording(
    originals: dict[str, bytes], tmp_path: Path
) -> None:
    path = tmp_path / "upload.db3"
    path.write_bytes(originals["db3"])
    _null_sqlite_topic(path)
    with pytest.raises(CorruptRecordingError, match="without a topic"):
        read_recording(path)
