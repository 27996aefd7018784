"""Read an MCAP file of the `ros1` profile (ROS 1 messages, as `mcap convert` writes from a ROS 1
bag) with the mcap library: rosbags reads only the `ros2` profile.

`Ros1McapReader` offers what `source.OpenRecording` uses of rosbags' readers (connections, times,
counts, raw messages in log-time order); messages are then decoded with the ROS 1 type store.
Each call into mcap (and rosbags' type system) is a `library_call`: what they raise on damaged
bytes is damage, what this module's own code raises is a bug.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO, Any

from mcap.reader import McapReader, make_reader
from mcap.records import Channel, Schema
from rosbags.interfaces import (
    Connection,
    ConnectionExtRosbag1,
    MessageDefinition,
    MessageDefinitionFormat,
)
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.msg import normalize_msgtype

from pipeline.io.errors import CorruptRecordingError
from pipeline.io.library_calls import guarded, library_call
from pipeline.io.typestores import ros1_typestore

ROS1_ENCODING = "ros1"


class Ros1McapReader:
    """One `ros1`-profile MCAP file; `open()` before use, `close()` after."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.connections: list[Connection] = []
        self.start_time = 2**63 - 1
        self.end_time = 0
        self.message_count = 0
        self._stream: IO[bytes] | None = None
        self._by_channel: dict[int, Connection] = {}

    def open(self) -> None:
        self._stream = self.path.open("rb")
        reader = self._reader()
        with library_call():
            summary = reader.get_summary()
        if summary is not None and summary.statistics is not None:
            schemas, channels = summary.schemas, summary.channels
            counts = dict(summary.statistics.channel_message_counts)
            if summary.statistics.message_count:
                self.start_time = summary.statistics.message_start_time
                self.end_time = summary.statistics.message_end_time + 1
        else:
            # No summary section (a recording cut short): one linear pass finds what it holds.
            schemas, channels, counts = {}, {}, {}
            everything = self._reader().iter_messages(log_time_order=False)
            for schema, channel, message in guarded(everything):
                if schema is not None:
                    schemas[schema.id] = schema
                channels[channel.id] = channel
                counts[channel.id] = counts.get(channel.id, 0) + 1
                self.start_time = min(self.start_time, message.log_time)
                self.end_time = max(self.end_time, message.log_time + 1)
        for channel_id in sorted(channels):
            channel = channels[channel_id]
            if channel.message_encoding != ROS1_ENCODING:
                continue
            schema = schemas.get(channel.schema_id)
            if schema is None:
                raise CorruptRecordingError(
                    f"{self.path}: channel {channel.topic} has no schema (message type); the "
                    "file is damaged: convert the ROS 1 bag again (`mcap convert`)"
                )
            connection = _connection(channel, schema, counts.get(channel_id, 0), self)
            self.connections.append(connection)
            self._by_channel[channel_id] = connection
        self.message_count = sum(c.msgcount for c in self.connections)

    def close(self) -> None:
        if self._stream is not None:
            self._stream.close()
            self._stream = None

    def messages(
        self, connections: Iterable[Connection] = ()
    ) -> Iterator[tuple[Connection, int, bytes]]:
        """`(connection, log time ns, raw ROS 1 bytes)` of those connections, by log time."""
        wanted = {c.id for c in connections} & set(self._by_channel)
        if not wanted:
            return
        topics = sorted({self._by_channel[i].topic for i in wanted})
        for _, channel, message in guarded(self._reader().iter_messages(topics=topics)):
            if channel.id in wanted:
                yield self._by_channel[channel.id], message.log_time, message.data

    def _reader(self) -> McapReader:
        assert self._stream is not None, "Ros1McapReader used before open()"
        self._stream.seek(0)
        with library_call():
            return make_reader(self._stream)


def _connection(channel: Channel, schema: Schema, count: int, owner: Any) -> Connection:
    with library_call():
        msgtype = normalize_msgtype(schema.name)
    definition = schema.data.decode()
    return Connection(
        id=channel.id,
        topic=channel.topic,
        msgtype=msgtype,
        msgdef=MessageDefinition(MessageDefinitionFormat.MSG, definition),
        digest=_md5sum(msgtype, definition),
        msgcount=count,
        ext=ConnectionExtRosbag1(
            callerid=channel.metadata.get("callerid"),
            latching=int(channel.metadata.get("latching", "0") or 0),
        ),
        owner=owner,
    )


def _md5sum(msgtype: str, definition: str) -> str:
    """The ROS 1 md5sum of the type (a ROS 1 bag stores it; the ros1 profile does not)."""
    store = ros1_typestore()
    with library_call():
        if msgtype not in store.types:
            store = get_typestore(Stores.EMPTY)
            store.register(get_types_from_msg(definition, msgtype))
        return store.generate_msgdef(msgtype, ros_version=1)[1]
