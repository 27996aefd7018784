"""What `fleetcal upload` sends: a recording file as it is, or a bag directory as a tar archived
on the fly; with its length, SHA-256 and an idempotency key derived from its content.

The archive is deterministic (sorted members, zero mtime, uid, gid, fixed modes), so the same
directory always hashes the same: a retried upload carries the same key and SHA-256, and the
service answers it with the first run instead of making a second one.
"""

from __future__ import annotations

import hashlib
import json
import tarfile
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from client.errors import BadInputError

CHUNK_BYTES = 1024 * 1024
_BLOCK = tarfile.BLOCKSIZE


@dataclass(frozen=True)
class Payload:
    """The body of an upload. `chunks()` can be read any number of times (each retry re-reads)."""

    source: Path
    size: int
    sha256: str
    _members: tuple[tuple[bytes, Path | None], ...]

    def chunks(self, on_chunk: Callable[[int], None] | None = None) -> Iterator[bytes]:
        for header, path in self._members:
            if header:
                yield header
                if on_chunk:
                    on_chunk(len(header))
            if path is None:
                continue
            written = 0
            with path.open("rb") as handle:
                while chunk := handle.read(CHUNK_BYTES):
                    written += len(chunk)
                    yield chunk
                    if on_chunk:
                        on_chunk(len(chunk))
            padding = -written % _BLOCK if header else 0
            if padding:
                yield b"\0" * padding
                if on_chunk:
                    on_chunk(padding)


def payload_for(path: Path) -> Payload:
    """The upload body of the recording at `path`: a file, or a ROS 2 bag directory (as tar)."""
    if path.is_file():
        members: tuple[tuple[bytes, Path | None], ...] = ((b"", path),)
    elif path.is_dir():
        members = _tar_members(path)
    else:
        raise BadInputError(f"{path} does not exist; pass a bag directory or a recording file")
    size = sum(len(h) + (_padded(p.stat().st_size, bool(h)) if p else 0) for h, p in members)
    if size == 0:
        raise BadInputError(f"{path} is empty; pass the recording the robot wrote")
    draft = Payload(source=path, size=size, sha256="", _members=members)
    digest = hashlib.sha256()
    try:
        for chunk in draft.chunks():
            digest.update(chunk)
    except OSError as err:
        raise BadInputError(f"cannot read {path} ({err})") from None
    return Payload(source=path, size=size, sha256=digest.hexdigest(), _members=members)


def idempotency_key(payload: Payload, kind: str, config: Mapping[str, Any] | None) -> str:
    """The same recording, kind and config give the same key: a retry is answered with the first
    run; another kind or config of the same recording is a new run."""
    canonical = json.dumps(config or {}, sort_keys=True, separators=(",", ":"))
    config_hash = hashlib.sha256(canonical.encode()).hexdigest()[:16]
    return f"fleetcal-upload:{kind}:{payload.sha256}:{config_hash}"


def _padded(size: int, in_tar: bool) -> int:
    return size + (-size % _BLOCK if in_tar else 0)


def _tar_members(directory: Path) -> tuple[tuple[bytes, Path | None], ...]:
    files = sorted(p for p in directory.rglob("*") if p.is_file())
    if not any(p.name == "metadata.yaml" for p in files):
        raise BadInputError(
            f"{directory} has no metadata.yaml: it is not a ROS 2 bag directory; pass the bag "
            "directory itself, or a recording file"
        )
    links = [p for p in directory.rglob("*") if p.is_symlink()]
    if links:
        raise BadInputError(f"{links[0]} is a link; the service refuses archives with links")
    members: list[tuple[bytes, Path | None]] = []
    for path in files:
        info = tarfile.TarInfo(f"{directory.name}/{path.relative_to(directory).as_posix()}")
        info.size = path.stat().st_size
        info.mode = 0o644
        info.mtime = 0
        members.append((info.tobuf(format=tarfile.PAX_FORMAT), path))
    members.append((b"\0" * (2 * _BLOCK), None))  # end of archive
    return tuple(members)
