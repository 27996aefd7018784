"""Archive uploads: the bag inside is found; traversal, links, specials and bombs are refused."""

from __future__ import annotations

import io
import os
import shutil
import stat
import tarfile
import zipfile
from pathlib import Path
from typing import Literal

import pytest

from pipeline.io import ReaderConfig, read_recording
from pipeline.io.archive import UnsafeArchiveError, extract_archive, find_recording
from pipeline.io.config import ArchiveLimits
from pipeline.io.errors import CorruptRecordingError, UnknownFormatError
from pipeline.io.formats import RecordingFormat

LIMITS = {"max_extracted_bytes": 1 << 20, "max_members": 10}


def _zip(path: Path, members: dict[str, bytes], *, link: str | None = None) -> Path:
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in members.items():
            archive.writestr(name, data)
        if link is not None:
            info = zipfile.ZipInfo(link)
            info.external_attr = (stat.S_IFLNK | 0o777) << 16
            archive.writestr(info, "/etc/passwd")
    return path


def _tar(path: Path, members: list[tarfile.TarInfo], mode: Literal["w", "w:gz"] = "w:gz") -> Path:
    with tarfile.open(path, mode) as archive:
        for member in members:
            data = b"x" * member.size if member.isfile() else None
            archive.addfile(member, io.BytesIO(data) if data is not None else None)
    return path


def _member(
    name: str, kind: bytes = tarfile.REGTYPE, size: int = 4, target: str = ""
) -> tarfile.TarInfo:
    member = tarfile.TarInfo(name)
    member.type, member.size, member.linkname = kind, size if kind == tarfile.REGTYPE else 0, target
    return member


def test_bag_directory_is_found_inside(tmp_path: Path) -> None:
    archive = _zip(tmp_path / "a.zip", {"run/bag/metadata.yaml": b"x", "run/bag/bag_0.mcap": b"y"})
    dest = tmp_path / "out"
    dest.mkdir()
    extract_archive(archive, RecordingFormat.ZIP, dest, **LIMITS)
    assert find_recording(dest, archive) == dest / "run" / "bag"


@pytest.mark.parametrize("name", ["../evil.mcap", "/etc/evil", "bag/../../evil", "C:\\evil"])
def test_path_traversal_is_refused(tmp_path: Path, name: str) -> None:
    archive = _zip(tmp_path / "a.zip", {name: b"x"})
    with pytest.raises(UnsafeArchiveError, match=r"outside the archive's folder"):
        extract_archive(archive, RecordingFormat.ZIP, tmp_path, **LIMITS)
    assert not (tmp_path.parent / "evil.mcap").exists()


def test_zip_symlink_is_refused(tmp_path: Path) -> None:
    archive = _zip(tmp_path / "a.zip", {"bag/metadata.yaml": b"x"}, link="bag/bag_0.mcap")
    with pytest.raises(UnsafeArchiveError, match=r"holds a link .*refused"):
        extract_archive(archive, RecordingFormat.ZIP, tmp_path, **LIMITS)
    assert not (tmp_path / "bag" / "bag_0.mcap").exists()


@pytest.mark.parametrize("kind", [tarfile.SYMTYPE, tarfile.LNKTYPE])
def test_tar_links_are_refused(tmp_path: Path, kind: bytes) -> None:
    archive = _tar(
        tmp_path / "a.tgz", [_member("bag/data"), _member("bag/x.mcap", kind, target="bag/data")]
    )
    dest = tmp_path / "o"
    dest.mkdir()
    with pytest.raises(UnsafeArchiveError, match=r"holds a link"):
        extract_archive(archive, RecordingFormat.TAR_GZ, dest, **LIMITS)


def test_tar_device_is_refused(tmp_path: Path) -> None:
    archive = _tar(tmp_path / "a.tar", [_member("bag/fifo", tarfile.FIFOTYPE)], mode="w")
    dest = tmp_path / "o"
    dest.mkdir()
    with pytest.raises(UnsafeArchiveError, match=r"not a regular file or folder"):
        extract_archive(archive, RecordingFormat.TAR, dest, **LIMITS)


def test_absurd_size_is_refused_before_writing(tmp_path: Path) -> None:
    archive = _tar(
        tmp_path / "a.tgz",
        [_member("bag/a.mcap", size=600_000), _member("bag/b.mcap", size=600_000)],
    )
    dest = tmp_path / "o"
    dest.mkdir()
    with pytest.raises(
        UnsafeArchiveError, match=r"expands to more than 0\.0 GiB .*max_extracted_bytes"
    ):
        extract_archive(archive, RecordingFormat.TAR_GZ, dest, **LIMITS)
    assert not (dest / "bag" / "b.mcap").exists()


def test_zip_device_is_refused(tmp_path: Path) -> None:
    archive = tmp_path / "a.zip"
    with zipfile.ZipFile(archive, "w") as zf:
        info = zipfile.ZipInfo("bag/dev")
        info.external_attr = (stat.S_IFCHR | 0o600) << 16
        zf.writestr(info, b"")
    with pytest.raises(UnsafeArchiveError, match=r"not a regular file or folder"):
        extract_archive(archive, RecordingFormat.ZIP, tmp_path, **LIMITS)


def test_zip_bomb_is_refused_from_its_declared_sizes(tmp_path: Path) -> None:
    archive = tmp_path / "bomb.zip"
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("bag/bag_0.mcap", b"\0" * (4 << 20))
    assert archive.stat().st_size < 50_000
    with pytest.raises(UnsafeArchiveError, match=r"expands to more than"):
        extract_archive(archive, RecordingFormat.ZIP, tmp_path, **LIMITS)


def test_too_many_members(tmp_path: Path) -> None:
    archive = _zip(tmp_path / "a.zip", {f"bag/{k}": b"" for k in range(11)})
    with pytest.raises(UnsafeArchiveError, match=r"more than 10 members"):
        extract_archive(archive, RecordingFormat.ZIP, tmp_path, **LIMITS)


def test_gzip_without_a_tar_inside_is_corrupt(tmp_path: Path) -> None:
    import gzip

    archive = tmp_path / "a.tar.gz"
    archive.write_bytes(gzip.compress(b"not a tar" * 100))
    with pytest.raises(CorruptRecordingError, match=r"tar.gz archive that cannot be unpacked"):
        read_recording(archive)


def test_archive_with_two_bags_or_none(tmp_path: Path) -> None:
    two = _zip(tmp_path / "two.zip", {"a/metadata.yaml": b"", "b/metadata.yaml": b""})
    with pytest.raises(UnknownFormatError, match=r"holds 2 bag directories \(a, b\)"):
        read_recording(two)
    none = _zip(tmp_path / "none.zip", {"notes.txt": b"hello"})
    with pytest.raises(UnknownFormatError, match=r"holds no recording"):
        read_recording(none)


def test_limits_come_from_the_reader_config(recordings: dict[str, Path]) -> None:
    config = ReaderConfig(archive=ArchiveLimits(max_members=1))
    with pytest.raises(UnsafeArchiveError, match=r"more than 1 members"):
        read_recording(recordings["zip"], config)


def test_scratch_directory_is_cleaned_up(recordings: dict[str, Path], tmp_path: Path) -> None:
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    config = ReaderConfig(scratch_dir=scratch)
    for name in ("zip", "bare-mcap-misnamed"):
        read_recording(recordings[name], config)
    with pytest.raises(UnknownFormatError):
        read_recording(_zip(tmp_path / "none.zip", {"x": b""}), config)
    assert list(scratch.iterdir()) == []


def test_fifo_in_bag_directory_does_not_hang(recordings: dict[str, Path], tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    shutil.copytree(recordings["ros2-mcap-dir"], bag)
    os.mkfifo(bag / "pipe")
    assert len(read_recording(bag).stops) == 3
