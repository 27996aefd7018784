"""Recognise a recording's format from its first bytes (never from its name)."""

from __future__ import annotations

import enum
from pathlib import Path

from pipeline.io.errors import EmptyRecordingError, UnknownFormatError

_MCAP_MAGIC = b"\x89MCAP0\r\n"
_SQLITE_MAGIC = b"SQLite format 3\x00"
_ROS1_MAGIC = b"#ROSBAG V2.0\n"
_ZIP_MAGICS = (b"PK\x03\x04", b"PK\x05\x06")
_GZIP_MAGIC = b"\x1f\x8b"
_TAR_MAGIC_OFFSET = 257
HEAD_BYTES = 512
"""How many leading bytes `detect_format_from_head` needs to tell every format apart."""


class RecordingFormat(enum.StrEnum):
    ROS2_DIRECTORY = "ros2-directory"
    MCAP = "mcap"
    SQLITE3 = "sqlite3"
    ROS1 = "ros1"
    MCAP_ROS1 = "mcap-ros1"
    """A storage, not a file format: an MCAP file of the `ros1` profile (ROS 1 messages)."""
    ZIP = "zip"
    TAR = "tar"
    TAR_GZ = "tar.gz"

    @property
    def is_archive(self) -> bool:
        return self in (RecordingFormat.ZIP, RecordingFormat.TAR, RecordingFormat.TAR_GZ)

    @property
    def holds_ros1_messages(self) -> bool:
        return self in (RecordingFormat.ROS1, RecordingFormat.MCAP_ROS1)


def detect_format_from_head(head: bytes) -> RecordingFormat | None:
    """The format whose magic bytes start `head` (the first `HEAD_BYTES` of a file), else None.

    A `.tar.gz` is recognised as gzip; whether it holds a tar is checked when it is opened.
    """
    if head.startswith(_MCAP_MAGIC):
        return RecordingFormat.MCAP
    if head.startswith(_SQLITE_MAGIC):
        return RecordingFormat.SQLITE3
    if head.startswith(_ROS1_MAGIC):
        return RecordingFormat.ROS1
    if head.startswith(_ZIP_MAGICS):
        return RecordingFormat.ZIP
    if head.startswith(_GZIP_MAGIC):
        return RecordingFormat.TAR_GZ
    if head[_TAR_MAGIC_OFFSET : _TAR_MAGIC_OFFSET + 5] == b"ustar":
        return RecordingFormat.TAR
    return None


def mcap_profile(head: bytes) -> str | None:
    """The profile (`ros2`, `ros1`, ...) in the header record that opens an MCAP file's `head`;
    None when `head` is no MCAP or is cut inside the header."""
    start = len(_MCAP_MAGIC)
    if not head.startswith(_MCAP_MAGIC) or head[start : start + 1] != b"\x01":
        return None
    length_at = start + 1 + 8  # opcode, then the record's uint64 length
    size = int.from_bytes(head[length_at : length_at + 4], "little")
    profile = head[length_at + 4 : length_at + 4 + size]
    if len(profile) != size:
        return None
    return profile.decode("utf-8", errors="replace")


def detect_format(path: Path) -> RecordingFormat:
    """The format of the file or bag directory at `path`.

    Raises `UnknownFormatError` with what was found and what is accepted.
    """
    path = Path(path)
    if path.is_dir():
        # metadata.yaml also marks a bag whose storage files are compressed (.mcap.zstd).
        if (path / "metadata.yaml").is_file() or any(
            _file_format(child) in (RecordingFormat.MCAP, RecordingFormat.SQLITE3)
            for child in sorted(path.iterdir())
            if child.is_file()
        ):
            return RecordingFormat.ROS2_DIRECTORY
        raise UnknownFormatError(
            f"{path} is a directory without a ROS 2 bag in it (no .mcap or .db3 storage file); "
            "pass a bag directory, a .mcap, .db3 or ROS 1 .bag file, "
            "or a .zip/.tar(.gz) of a bag directory"
        )
    if not path.exists():
        raise UnknownFormatError(f"{path} does not exist; check the path")
    found = _file_format(path)
    if found is None and path.is_file() and path.stat().st_size == 0:
        raise EmptyRecordingError(
            f"{path} is empty (0 bytes): the recording was not written or not copied in full; "
            "copy or upload it again"
        )
    if found is None:
        raise UnknownFormatError(
            f"{path} is not a recording we can read (its first bytes match no known format); "
            "accepted: ROS 2 bag directory (MCAP or sqlite3), bare .mcap or .db3, ROS 1 .bag, "
            "or a .zip/.tar/.tar.gz holding a ROS 2 bag directory"
        )
    return found


def _file_format(path: Path) -> RecordingFormat | None:
    try:
        with path.open("rb") as stream:
            head = stream.read(HEAD_BYTES)
    except OSError as err:
        raise UnknownFormatError(
            f"cannot read {path}: {err.strerror}; check the path and permissions"
        ) from err
    return detect_format_from_head(head)
