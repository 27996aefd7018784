"""The LiDARs of a recording without reading all of it: each PointCloud2 topic's frame, from its
first scan (`fleetcal export --format recording` checks a result against them)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pipeline.io.config import ArchiveLimits
from pipeline.io.source import connections_of, open_recording, reading_errors
from pipeline.io.tf_tree import normalize_frame
from pipeline.io.typestores import POINTCLOUD2


def lidar_frames(
    path: Path | str, *, limits: ArchiveLimits | None = None, scratch_dir: Path | None = None
) -> dict[str, str]:
    """`{topic: frame}` of every PointCloud2 topic with a scan in the recording at `path`, by
    topic. Reads up to each topic's first scan; raises `RecordingError` like the reader."""
    frames: dict[str, str] = {}
    with open_recording(Path(path), limits=limits, scratch_dir=scratch_dir) as opened:
        topics = connections_of(opened, POINTCLOUD2)
        connections = [c for group in topics.values() for c in group]
        with reading_errors(opened.path, opened.storage):
            for connection, _, raw in opened.messages(connections):
                if connection.topic not in frames:
                    msg: Any = opened.deserialize(raw, connection)
                    frames[connection.topic] = normalize_frame(msg.header.frame_id)
                if len(frames) == len(topics):
                    break
    return dict(sorted(frames.items()))
