"""Errors while reading a recording: the libraries' failures become `CorruptRecordingError` with a
remedy, known from where they were caught; the same kinds of error from our code stay bugs."""

from __future__ import annotations

import contextlib
import shutil
import sqlite3
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from rosbags import rosbag1, rosbag2
from rosbags.typesys.store import Typestore

from pipeline.io import read_recording
from pipeline.io.errors import CorruptRecordingError, NoStopsError
from pipeline.io.formats import RecordingFormat
from pipeline.io.library_calls import LibraryError
from pipeline.io.source import reading_errors

PATH = Path("robot.bag")


def test_a_library_error_is_damage_with_a_remedy() -> None:
    cause = IndexError("list index out of range")
    with pytest.raises(CorruptRecordingError) as caught, reading_errors(PATH, RecordingFormat.ROS1):
        raise LibraryError(cause)
    assert str(caught.value) == (
        "robot.bag looks like a ros1 recording but cannot be read (list index out of range); it "
        "is truncated or damaged: run `rosbag reindex` on it, or copy it again"
    )
    assert caught.value.__cause__ is cause


def test_a_read_error_is_damage_wherever_it_is_raised() -> None:
    damaged = pytest.raises(CorruptRecordingError, match=r"cannot be read \(unpack requires")
    with damaged, reading_errors(PATH, RecordingFormat.MCAP):
        struct.unpack("<I", b"\x00")


def test_a_plain_error_of_ours_stays_a_bug() -> None:
    with pytest.raises(ValueError, match="ours"), reading_errors(PATH, RecordingFormat.MCAP):
        raise ValueError("ours")


def test_a_recording_error_passes_unchanged() -> None:
    raised = NoStopsError("no stops")
    with pytest.raises(NoStopsError) as caught, reading_errors(PATH, RecordingFormat.MCAP):
        raise raised
    assert caught.value is raised


def _fails_after(original: Any, count: int, error: Exception) -> Any:
    """`original` (a reader's `messages`) that raises `error` after `count` messages."""

    def messages(self: Any, *args: Any, **kwargs: Any) -> Iterator[Any]:
        for index, message in enumerate(original(self, *args, **kwargs)):
            if index == count:
                raise error
            yield message

    return messages


@pytest.mark.parametrize(
    ("name", "reader"), [("bare-mcap", rosbag2.Reader), ("ros1", rosbag1.Reader)]
)
def test_a_plain_error_while_rosbags_reads_messages_is_damage(
    name: str, reader: Any, recordings: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    failing = _fails_after(reader.messages, 5, KeyError("chunk 7"))
    monkeypatch.setattr(reader, "messages", failing)
    with pytest.raises(CorruptRecordingError, match=r"cannot be read \('chunk 7'\); it is trunc"):
        read_recording(recordings[name])


def test_a_plain_error_while_rosbags_decodes_is_damage(
    recordings: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    def deserialize_cdr(self: Typestore, raw: bytes, msgtype: str) -> Any:
        raise AssertionError("bad alignment")

    monkeypatch.setattr(Typestore, "deserialize_cdr", deserialize_cdr)
    with pytest.raises(CorruptRecordingError, match=r"cannot be read \(bad alignment\)"):
        read_recording(recordings["bare-mcap"])


def test_the_same_error_from_our_decoding_stays_a_bug(
    recordings: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    def field_names(msg: Any) -> tuple[str, ...]:
        raise KeyError("a bug of ours")

    monkeypatch.setattr("pipeline.io.reader.field_names", field_names)
    with pytest.raises(KeyError, match="a bug of ours"):
        read_recording(recordings["bare-mcap"])


@pytest.mark.parametrize("column", ["timestamp", "data"])
def test_a_sqlite3_row_with_a_null_is_damage(
    column: str, recordings: dict[str, Path], tmp_path: Path
) -> None:
    # A damaged page can leave a row's timestamp or data NULL; rosbags hands it on as None.
    bag = Path(shutil.copy(recordings["bare-db3"], tmp_path / "damaged.db3"))
    with contextlib.closing(sqlite3.connect(bag)) as db, db:
        # The damage bypasses the schema's NOT NULL, which a plain UPDATE would enforce.
        db.execute("PRAGMA writable_schema = ON")
        db.execute(
            "UPDATE sqlite_master SET sql = replace(sql, 'NOT NULL', '') WHERE name = 'messages'"
        )
    with contextlib.closing(sqlite3.connect(bag)) as db, db:
        db.execute(f"UPDATE messages SET {column} = NULL WHERE id = 7")
    with pytest.raises(CorruptRecordingError, match=r"a message on /\S+ has log time"):
        read_recording(bag)
