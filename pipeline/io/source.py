"""Open any supported recording with rosbags' readers, whatever its name, and translate errors.

rosbags chooses its back-end by file suffix, but we trust only magic bytes; a file whose name
does not say what it is gets a correctly named symlink in a scratch folder. Archives are unpacked
there too (see `archive`). Messages of the standard types are decoded with our type stores, which
are built once per process; rosbags' `AnyReader` would parse every embedded definition again at
each open (a quarter of a 100 MB read), so the plain readers are used and merged here.
"""

from __future__ import annotations

import heapq
import os
import struct
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any, cast

import apsw
import yaml
import zstandard
from mcap.exceptions import McapError
from rosbags import rosbag1, rosbag2
from rosbags.interfaces import Connection
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, TypesysError, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from pipeline.io.archive import extract_archive, find_recording
from pipeline.io.config import ArchiveLimits
from pipeline.io.errors import CorruptRecordingError, RecordingError, UnknownFormatError
from pipeline.io.formats import (
    HEAD_BYTES,
    RecordingFormat,
    _file_format,
    detect_format,
    mcap_profile,
)
from pipeline.io.library_calls import LIBRARY_ERRORS, LibraryError, guarded, library_call
from pipeline.io.mcap_ros1 import Ros1McapReader
from pipeline.io.typestores import ros1_typestore, ros2_typestore

_ROS2_STORAGES = (RecordingFormat.MCAP, RecordingFormat.SQLITE3)
_SUFFIX = {
    RecordingFormat.MCAP: ".mcap",
    RecordingFormat.SQLITE3: ".db3",
    RecordingFormat.ROS1: ".bag",
}

# What rosbags and its back-ends raise on a damaged or truncated file: damage wherever raised.
# (Plain errors such as ValueError count as damage only from inside a library call: see
# `library_calls`.)
READ_ERRORS: tuple[type[BaseException], ...] = (
    rosbag1.ReaderError,
    rosbag2.ReaderError,
    SerdeError,
    TypesysError,
    apsw.Error,
    struct.error,
    EOFError,
    OSError,
    RuntimeError,  # lz4 frame errors in ROS 1 chunks
    UnicodeDecodeError,  # damaged names and definitions
    McapError,  # the mcap library (ros1-profile MCAP)
    zstandard.ZstdError,
)


class RosbagsReader:
    """rosbags' reader of one bag file or directory, every call made as a `library_call`: the
    counterpart of `Ros1McapReader`, which guards its own calls into mcap."""

    def __init__(self, bag: Path, storage: RecordingFormat) -> None:
        with library_call():
            self._reader = (
                rosbag1.Reader(bag) if storage is RecordingFormat.ROS1 else rosbag2.Reader(bag)
            )

    def open(self) -> None:
        with library_call():
            self._reader.open()

    def close(self) -> None:
        with library_call():
            self._reader.close()

    @property
    def connections(self) -> list[Connection]:
        with library_call():
            return list(self._reader.connections)

    @property
    def start_time(self) -> int:
        with library_call():
            return self._reader.start_time

    @property
    def end_time(self) -> int:
        with library_call():
            return self._reader.end_time

    @property
    def message_count(self) -> int:
        with library_call():
            return self._reader.message_count

    def messages(
        self, connections: Sequence[Connection]
    ) -> Iterator[tuple[Connection, int, bytes]]:
        """`(connection, log time ns, raw bytes)` of those connections, in log-time order."""
        with library_call():
            messages = self._reader.messages(connections=connections)
        return _well_formed(guarded(iter(messages)))


def _well_formed(
    messages: Iterator[tuple[Connection, Any, Any]],
) -> Iterator[tuple[Connection, int, bytes]]:
    """`messages` as rosbags yields them, each checked to have an integer log time and bytes:
    a damaged sqlite3 bag can hold a row whose timestamp or data is NULL, which rosbags passes
    on as None (a `LibraryError`, so the recording is reported damaged)."""
    for connection, log_ns, raw in messages:
        # (Damaged sqlite3 rows can also hold a REAL or TEXT where an integer or a BLOB was.)
        if not isinstance(log_ns, int) or not isinstance(raw, bytes | memoryview):
            raise LibraryError(
                ValueError(
                    f"a message on {connection.topic} has log time {log_ns!r} and "
                    f"{type(raw).__name__} data"
                )
            )
        yield connection, log_ns, cast(bytes, raw)


class OpenRecording:
    """An open recording: the path given, its format, its storage, and its messages. What it
    raises about the recording is already a `RecordingError` naming `path`."""

    def __init__(
        self,
        path: Path,
        fmt: RecordingFormat,
        storage: RecordingFormat,
        readers: Sequence[RosbagsReader | Ros1McapReader],
    ) -> None:
        self.path, self.format, self.storage = path, fmt, storage
        self._readers = readers
        self._store = ros1_typestore() if storage.holds_ros1_messages else ros2_typestore()
        self._other_types: dict[str, Typestore] = {}

    @property
    def connections(self) -> list[Connection]:
        with reading_errors(self.path, self.storage):
            return [c for reader in self._readers for c in reader.connections]

    @property
    def start_time(self) -> int:
        with reading_errors(self.path, self.storage):
            return min(reader.start_time for reader in self._readers)

    @property
    def end_time(self) -> int:
        with reading_errors(self.path, self.storage):
            return max(reader.end_time for reader in self._readers)

    @property
    def message_count(self) -> int:
        with reading_errors(self.path, self.storage):
            return sum(reader.message_count for reader in self._readers)

    def messages(
        self, connections: Iterable[Connection]
    ) -> Iterator[tuple[Connection, int, bytes]]:
        """`(connection, log time ns, raw bytes)` of those connections, in log-time order."""
        wanted = set(map(id, connections))
        with reading_errors(self.path, self.storage):
            streams = []
            for reader in self._readers:
                mine = [c for c in reader.connections if id(c) in wanted]
                if mine:
                    streams.append(reader.messages(connections=mine))
            yield from heapq.merge(*streams, key=lambda message: message[1])

    def deserialize(self, raw: bytes, connection: Connection) -> Any:
        """Decode one message; standard types with our process-wide type store."""
        msgtype = connection.msgtype
        store = self._store
        try:
            if msgtype not in store.types:
                store = self._other_types.get(msgtype) or self._store_for(connection)
            if self.storage.holds_ros1_messages:
                return store.deserialize_ros1(raw, msgtype)
            return store.deserialize_cdr(raw, msgtype)
        except LIBRARY_ERRORS as err:
            raise _damaged(self.path, self.storage, err) from err

    def _store_for(self, connection: Connection) -> Typestore:
        """A type store for a type ours lacks (e.g. ROS 1 `tf/tfMessage`), built once from the
        definition the recording carries."""
        store = get_typestore(Stores.EMPTY)
        store.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
        self._other_types[connection.msgtype] = store
        return store


@contextmanager
def reading_errors(path: Path, storage: RecordingFormat) -> Iterator[None]:
    """Turn an error of the libraries while reading `path` into `CorruptRecordingError` with a
    remedy: their own error types (`READ_ERRORS`) wherever raised, plain Python errors only when
    a library call raised them (`LibraryError`); the same plain errors from our code stay bugs."""
    try:
        yield
    except RecordingError:
        raise
    except LibraryError as err:
        raise _damaged(path, storage, err.cause) from err.cause
    except READ_ERRORS as err:
        raise _damaged(path, storage, err) from err


def _damaged(path: Path, storage: RecordingFormat, err: BaseException) -> CorruptRecordingError:
    return CorruptRecordingError(
        f"{path} looks like a {storage.value} recording but cannot be read ({_cause(err)}); "
        f"it is truncated or damaged: {_remedy(storage)}"
    )


def _remedy(storage: RecordingFormat) -> str:
    return {
        RecordingFormat.ROS1: "run `rosbag reindex` on it, or copy it again",
        RecordingFormat.SQLITE3: "copy it again; a damaged sqlite3 bag cannot be repaired here",
    }.get(storage, "copy it again, or repair it with `ros2 bag reindex` / `mcap recover`")


@contextmanager
def open_recording(
    path: Path, *, limits: ArchiveLimits | None = None, scratch_dir: Path | None = None
) -> Iterator[OpenRecording]:
    """Open the recording at `path` (bag directory, bare storage file, ROS 1 bag, or archive)."""
    path = Path(path)
    limits = limits or ArchiveLimits()
    fmt = detect_format(path)
    with ExitStack() as stack:
        scratch: list[Path] = []

        def scratch_path() -> Path:
            if not scratch:
                scratch.append(
                    Path(
                        stack.enter_context(
                            tempfile.TemporaryDirectory(prefix="fleetcal-", dir=scratch_dir)
                        )
                    )
                )
            return scratch[0]

        inner, inner_fmt = path, fmt
        if fmt.is_archive:
            unpacked = scratch_path() / "unpacked"
            unpacked.mkdir()
            extract_archive(
                path,
                fmt,
                unpacked,
                max_extracted_bytes=limits.max_extracted_bytes,
                max_members=limits.max_members,
            )
            inner = find_recording(unpacked, path)
            inner_fmt = detect_format(inner)
        storage = _storage_format(inner, inner_fmt)
        if inner_fmt is RecordingFormat.ROS2_DIRECTORY and (inner / "metadata.yaml").exists():
            # The directory reader also knows the compression and the split files' order.
            paths = [inner]
        else:
            files = (
                _storage_files(inner) if inner_fmt is RecordingFormat.ROS2_DIRECTORY else [inner]
            )
            paths = [_named_for_rosbags(f, storage, i, scratch_path) for i, f in enumerate(files)]
        with reading_errors(path, storage):
            readers: list[RosbagsReader | Ros1McapReader] = []
            for bag in paths:
                reader = _reader(bag, storage)
                reader.open()
                stack.callback(reader.close)
                readers.append(reader)
        for connection in (c for reader in readers for c in reader.connections):
            # A damaged sqlite3 bag can hand back NULL topics or types.
            if not isinstance(connection.topic, str) or not isinstance(connection.msgtype, str):
                raise CorruptRecordingError(
                    f"{path} has a connection without a topic or message type "
                    f"({connection.topic!r}, {connection.msgtype!r}); it is damaged: "
                    f"{_remedy(storage)}"
                )
        yield OpenRecording(path, fmt, storage, readers)


def _reader(bag: Path, storage: RecordingFormat) -> RosbagsReader | Ros1McapReader:
    if storage is RecordingFormat.MCAP_ROS1:
        return Ros1McapReader(bag)
    return RosbagsReader(bag, storage)


def _storage_format(path: Path, fmt: RecordingFormat) -> RecordingFormat:
    """MCAP (ros2 or ros1 profile), sqlite3 or ROS 1: what the reader will find inside."""
    if fmt is RecordingFormat.MCAP:
        return _mcap_storage(path)
    if fmt is not RecordingFormat.ROS2_DIRECTORY:
        return fmt
    declared = _declared_storage(path / "metadata.yaml")
    if declared is not None:
        return declared
    kinds = {kind for child in _storage_files(path) if (kind := _file_format(child)) is not None}
    if len(kinds) > 1:
        raise CorruptRecordingError(
            f"{path} mixes MCAP and sqlite3 storage files; a bag directory holds one kind"
        )
    return kinds.pop()


def _mcap_storage(path: Path) -> RecordingFormat:
    """MCAP with ROS 2 messages, or with ROS 1 messages (`mcap convert` of a ROS 1 bag)."""
    with path.open("rb") as stream:
        profile = mcap_profile(stream.read(HEAD_BYTES))
    if profile == "ros1":
        return RecordingFormat.MCAP_ROS1
    if profile in ("ros2", None):  # None: a damaged header, which rosbags will report
        return RecordingFormat.MCAP
    raise UnknownFormatError(
        f"{path} is an MCAP file of profile {profile!r}, not of ROS messages; fleetcal reads MCAP "
        "written by `ros2 bag record` (profile ros2) or converted from a ROS 1 bag by "
        "`mcap convert` (profile ros1)"
    )


def _declared_storage(metadata: Path) -> RecordingFormat | None:
    """The storage a bag's metadata.yaml names (its files may be compressed, so no magic)."""
    if not metadata.is_file():
        return None
    try:
        info = yaml.safe_load(metadata.read_text())["rosbag2_bagfile_information"]
        identifier = str(info["storage_identifier"])
    except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError) as err:
        raise CorruptRecordingError(
            f"{metadata} cannot be read ({_cause(err)}); it is damaged: copy the bag directory "
            "again, or remove metadata.yaml to read the storage files alone"
        ) from err
    return {"mcap": RecordingFormat.MCAP, "sqlite3": RecordingFormat.SQLITE3}.get(identifier)


def _storage_files(directory: Path) -> list[Path]:
    """The MCAP / sqlite3 files of a bag directory, by name (the order `ros2 bag` splits them)."""
    return [
        child
        for child in sorted(directory.iterdir())
        if child.is_file() and _file_format(child) in _ROS2_STORAGES
    ]


def _named_for_rosbags(
    path: Path, storage: RecordingFormat, index: int, scratch: Callable[[], Path]
) -> Path:
    suffix = _SUFFIX.get(storage)
    if suffix is None or path.suffix == suffix:  # the mcap library does not look at names
        return path
    link = scratch() / f"{index:04d}-{path.stem}{suffix}"
    os.symlink(path.resolve(), link)
    return link


def _cause(err: BaseException) -> str:
    text = " ".join(str(err).split()) or type(err).__name__  # one line, whatever the library wrote
    return text if len(text) < 200 else text[:200] + "..."


def stamp_ns(header: Any) -> int:
    """A `std_msgs/Header`'s stamp in integer nanoseconds (0 when the publisher left it unset)."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def connections_of(opened: OpenRecording, msgtype: str) -> dict[str, list[Connection]]:
    """Connections of `msgtype` by topic, topics sorted (a ROS 1 topic may have several)."""
    grouped: dict[str, list[Connection]] = {}
    for connection in sorted(opened.connections, key=lambda c: (c.topic, c.id)):
        if connection.msgtype == msgtype:
            grouped.setdefault(connection.topic, []).append(connection)
    return grouped
