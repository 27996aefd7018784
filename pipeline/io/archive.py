"""Unpack an uploaded `.zip` / `.tar` / `.tar.gz` safely and find the recording inside.

Every member is checked before it is written: no absolute paths or `..`, no links or device
files, and a cap on the number of members and on the bytes they expand to (checked against the
declared sizes, which both formats then enforce while reading, and against the free disk space).
"""

from __future__ import annotations

import shutil
import stat
import tarfile
import zipfile
import zlib
from pathlib import Path, PurePosixPath
from typing import IO

from pipeline.io.errors import CorruptRecordingError, UnknownFormatError
from pipeline.io.formats import RecordingFormat, _file_format

_COPY_CHUNK = 1 << 20
_ARCHIVE_ERRORS = (zipfile.BadZipFile, tarfile.TarError, zlib.error, EOFError, OSError)


class UnsafeArchiveError(CorruptRecordingError):
    """The archive tries to write outside its folder, holds links, or expands to an absurd size."""


def extract_archive(
    path: Path,
    fmt: RecordingFormat,
    dest: Path,
    *,
    max_extracted_bytes: int,
    max_members: int,
) -> None:
    """Unpack the archive at `path` (`fmt` from its magic bytes) into the empty folder `dest`."""
    try:
        if fmt is RecordingFormat.ZIP:
            _extract_zip(path, dest, max_extracted_bytes, max_members)
        else:
            _extract_tar(path, dest, max_extracted_bytes, max_members)
    except UnsafeArchiveError:
        raise
    except _ARCHIVE_ERRORS as err:
        raise CorruptRecordingError(
            f"{path} is a {fmt.value} archive that cannot be unpacked ({err}); it is damaged or "
            "truncated: create it again from the ROS 2 bag directory"
        ) from err


def find_recording(root: Path, archive: Path) -> Path:
    """The one recording in an unpacked archive: a bag directory, or a lone bag file."""
    bag_dirs = sorted(meta.parent for meta in root.rglob("metadata.yaml"))
    if len(bag_dirs) == 1:
        return bag_dirs[0]
    if len(bag_dirs) > 1:
        names = [str(d.relative_to(root)) for d in bag_dirs]
        raise UnknownFormatError(
            f"{archive} holds {len(bag_dirs)} bag directories ({', '.join(names)}); "
            "upload one recording per archive"
        )
    found = {p: _file_format(p) for p in sorted(root.rglob("*")) if p.is_file()}
    bags = {
        p: f
        for p, f in found.items()
        if f in (RecordingFormat.MCAP, RecordingFormat.SQLITE3, RecordingFormat.ROS1)
    }
    parents = {p.parent for p in bags}
    if len(bags) == 1:
        return next(iter(bags))
    if len(parents) == 1 and RecordingFormat.ROS1 not in bags.values():
        return parents.pop()  # split ROS 2 storage files without their metadata.yaml
    if not bags:
        raise UnknownFormatError(
            f"{archive} holds no recording (no metadata.yaml, .mcap, .db3 or .bag among "
            f"{len(found)} files); archive the ROS 2 bag directory itself"
        )
    raise UnknownFormatError(
        f"{archive} holds {len(bags)} recordings in different folders; "
        "upload one recording per archive"
    )


def _extract_zip(path: Path, dest: Path, max_bytes: int, max_members: int) -> None:
    with zipfile.ZipFile(path) as archive:
        infos = archive.infolist()
        _check_totals(
            path, dest, len(infos), sum(i.file_size for i in infos), max_bytes, max_members
        )
        for info in infos:
            target = _target(dest, info.filename, path)
            mode = info.external_attr >> 16
            if stat.S_ISLNK(mode):
                raise _link_error(path, info.filename)
            if info.is_dir():
                target.mkdir(parents=True, exist_ok=True)
                continue
            # Windows tools and Python's writestr leave the type bits empty: only permissions.
            if stat.S_IFMT(mode) not in (0, stat.S_IFREG, stat.S_IFDIR):
                raise _special_error(path, info.filename)
            with archive.open(info) as source:
                _write(source, target)


def _extract_tar(path: Path, dest: Path, max_bytes: int, max_members: int) -> None:
    total = 0
    # Stream mode reads a .tar.gz once, front to back, without seeking in the gzip stream.
    with tarfile.open(path, mode="r|*") as archive:
        for count, member in enumerate(archive, start=1):
            target = _target(dest, member.name, path)
            if member.issym() or member.islnk():
                raise _link_error(path, member.name)
            if member.isdir():
                target.mkdir(parents=True, exist_ok=True)
                continue
            if not member.isfile():
                raise _special_error(path, member.name)
            total += member.size
            _check_totals(path, dest, count, total, max_bytes, max_members)
            source = archive.extractfile(member)
            assert source is not None  # a regular file always has a stream
            with source:
                _write(source, target)


def _target(dest: Path, name: str, archive: Path) -> Path:
    parts = PurePosixPath(name.replace("\\", "/")).parts
    if not parts or parts[0] == "/" or ".." in parts or ":" in parts[0]:
        raise UnsafeArchiveError(
            f"{archive} has a member named {name!r} that would be written outside the archive's "
            "folder; refusing it. Archive the bag directory with relative paths"
        )
    return dest.joinpath(*parts)


def _check_totals(
    archive: Path, dest: Path, members: int, total: int, max_bytes: int, max_members: int
) -> None:
    if members > max_members:
        raise UnsafeArchiveError(
            f"{archive} holds more than {max_members} members; a recording has a handful. "
            "Archive only the bag directory"
        )
    if total > max_bytes:
        raise UnsafeArchiveError(
            f"{archive} expands to more than {max_bytes / 2**30:.1f} GiB "
            f"({total / 2**30:.1f} GiB declared); refusing it. Upload a shorter recording or "
            "raise archive.max_extracted_bytes in the reader config"
        )
    free = shutil.disk_usage(dest).free
    if total > free:
        raise UnsafeArchiveError(
            f"{archive} expands to {total / 2**30:.2f} GiB but only {free / 2**30:.2f} GiB are "
            f"free in {dest.parent}; free some space or set scratch_dir in the reader config"
        )


def _write(source: IO[bytes], target: Path) -> None:
    target.parent.mkdir(parents=True, exist_ok=True)
    with target.open("xb") as sink:
        shutil.copyfileobj(source, sink, _COPY_CHUNK)


def _link_error(archive: Path, name: str) -> UnsafeArchiveError:
    return UnsafeArchiveError(
        f"{archive} holds a link ({name!r}); links are refused in uploads. "
        "Archive the bag directory's files themselves (e.g. `tar -chzf` or `zip -r` without -y)"
    )


def _special_error(archive: Path, name: str) -> UnsafeArchiveError:
    return UnsafeArchiveError(
        f"{archive} holds {name!r}, which is not a regular file or folder (a device or pipe); "
        "archive only the bag directory"
    )
