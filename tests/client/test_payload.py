"""The upload body: a bag directory as a deterministic tar that tarfile reads back, its SHA-256,
and an idempotency key that follows the recording, kind and config."""

from __future__ import annotations

import hashlib
import io
import tarfile
from pathlib import Path

import pytest

from client.errors import BadInputError
from client.payload import idempotency_key, payload_for


def bag(directory: Path) -> Path:
    directory.mkdir()
    (directory / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (directory / "bag_0.mcap").write_bytes(b"\x89MCAP0\r\n" + b"x" * 1500)
    return directory


def test_a_bag_directory_streams_as_a_tar_that_reads_back(tmp_path: Path) -> None:
    payload = payload_for(bag(tmp_path / "rec"))
    body = b"".join(payload.chunks())
    assert len(body) == payload.size
    assert hashlib.sha256(body).hexdigest() == payload.sha256
    with tarfile.open(fileobj=io.BytesIO(body)) as tar:
        assert tar.getnames() == ["rec/bag_0.mcap", "rec/metadata.yaml"]
        member = tar.extractfile("rec/bag_0.mcap")
        assert member is not None and member.read() == (tmp_path / "rec/bag_0.mcap").read_bytes()


def test_the_same_recording_gives_the_same_key_whatever_its_mtimes(tmp_path: Path) -> None:
    first = payload_for(bag(tmp_path / "rec"))
    (tmp_path / "rec/bag_0.mcap").touch()
    again = payload_for(tmp_path / "rec")
    assert again.sha256 == first.sha256
    assert idempotency_key(again, "end_of_line", None) == idempotency_key(first, "end_of_line", {})
    assert idempotency_key(first, "maintenance", None) != idempotency_key(
        first, "end_of_line", None
    )
    config = {"frames": {"reference_frame": "lidar_rear"}}
    assert idempotency_key(first, "end_of_line", config) != idempotency_key(
        first, "end_of_line", None
    )
    assert len(idempotency_key(first, "end_of_line", config)) <= 255


def test_a_file_is_sent_as_it_is(tmp_path: Path) -> None:
    path = tmp_path / "r.mcap"
    path.write_bytes(b"\x89MCAP0\r\n1234")
    payload = payload_for(path)
    assert b"".join(payload.chunks()) == path.read_bytes()
    assert payload.sha256 == hashlib.sha256(path.read_bytes()).hexdigest()


def test_a_directory_without_metadata_is_refused(tmp_path: Path) -> None:
    (tmp_path / "photos").mkdir()
    (tmp_path / "photos/a.jpg").write_bytes(b"x")
    with pytest.raises(BadInputError, match=r"no metadata\.yaml: it is not a ROS 2 bag directory"):
        payload_for(tmp_path / "photos")


def test_an_empty_file_is_refused(tmp_path: Path) -> None:
    (tmp_path / "empty.mcap").touch()
    with pytest.raises(BadInputError, match="is empty"):
        payload_for(tmp_path / "empty.mcap")


def test_a_link_in_the_bag_is_refused(tmp_path: Path) -> None:
    directory = bag(tmp_path / "rec")
    (directory / "extra.mcap").symlink_to(directory / "bag_0.mcap")
    with pytest.raises(BadInputError, match="is a link"):
        payload_for(directory)
