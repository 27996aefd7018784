"""Format detection by magic bytes, whatever the file is called."""

import io
import tarfile
import zipfile
from pathlib import Path

import numpy as np
import pytest

from pipeline.io.errors import UnknownFormatError
from pipeline.io.formats import RecordingFormat, detect_format
from pipeline.io.writer import RecordingWriter, WriterFormat


def write_small(path: Path, fmt: WriterFormat) -> None:
    with RecordingWriter(path, fmt) as writer:
        writer.write_pointcloud("/lidar/points", 1, "lidar", np.zeros((3, 3)))


@pytest.mark.parametrize(
    ("fmt", "expected"),
    [
        (WriterFormat.ROS2_MCAP, RecordingFormat.MCAP),
        (WriterFormat.ROS2_SQLITE3, RecordingFormat.SQLITE3),
    ],
)
def test_ros2_directory_and_its_storage_file(
    tmp_path: Path, fmt: WriterFormat, expected: RecordingFormat
) -> None:
    bag = tmp_path / "bag"
    write_small(bag, fmt)
    assert detect_format(bag) is RecordingFormat.ROS2_DIRECTORY
    storage = next(p for p in bag.iterdir() if p.suffix in (".mcap", ".db3"))
    renamed = storage.rename(tmp_path / "misleading.txt")
    assert detect_format(renamed) is expected


def test_ros1_bag_detected_without_its_extension(tmp_path: Path) -> None:
    bag = tmp_path / "recording.bag"
    write_small(bag, WriterFormat.ROS1)
    assert detect_format(bag.rename(tmp_path / "recording.mcap")) is RecordingFormat.ROS1


def test_archives(tmp_path: Path) -> None:
    zipped = tmp_path / "a.tar"  # a zip named like a tar
    with zipfile.ZipFile(zipped, "w") as archive:
        archive.writestr("bag/metadata.yaml", "x")
    assert detect_format(zipped) is RecordingFormat.ZIP

    tarred = tmp_path / "b.zip"
    with tarfile.open(tarred, "w") as archive:
        data = b"hello"
        info = tarfile.TarInfo("bag/file")
        info.size = len(data)
        archive.addfile(info, io.BytesIO(data))
    assert detect_format(tarred) is RecordingFormat.TAR

    gzipped = tmp_path / "c.bin"
    with tarfile.open(gzipped, "w:gz") as archive:
        archive.addfile(tarfile.TarInfo("empty"), io.BytesIO(b""))
    assert detect_format(gzipped) is RecordingFormat.TAR_GZ


def test_unknown_file_names_what_is_accepted(tmp_path: Path) -> None:
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"\x00" * 600)
    with pytest.raises(UnknownFormatError, match="accepted: ROS 2 bag directory"):
        detect_format(junk)


def test_missing_path_and_empty_directory(tmp_path: Path) -> None:
    with pytest.raises(UnknownFormatError, match="does not exist"):
        detect_format(tmp_path / "nope")
    with pytest.raises(UnknownFormatError, match="without a ROS 2 bag"):
        detect_format(tmp_path)
