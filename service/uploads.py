"""Streaming a request body into storage: size limit, SHA-256 on the fly, magic-byte check.

The body is never held whole: chunks gather into blocks of `BLOCK_BYTES`, each hashed and written
in a worker thread (hashlib and file writes release the GIL) while the event loop keeps serving.
On any failure, disconnect included, the pending object is aborted: nothing partial survives.
Storage errors propagate as `StorageError`; `service.problems` maps them (503, or 507 when full).
"""

from __future__ import annotations

import hashlib
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from typing import ParamSpec, TypeVar

import anyio
from anyio import to_thread
from starlette.requests import ClientDisconnect

from pipeline.io.formats import HEAD_BYTES, RecordingFormat, detect_format_from_head
from service.problems import (
    ChecksumMismatch,
    ClientDisconnected,
    ContentLengthMismatch,
    EmptyUpload,
    UnsupportedRecording,
    UploadTooLarge,
)
from service.storage import PendingUpload, Storage

P = ParamSpec("P")
T = TypeVar("T")

BLOCK_BYTES = 1024 * 1024
ACCEPTED = (
    "MCAP (.mcap), ROS 2 sqlite3 (.db3), ROS 1 (.bag), or a .zip/.tar/.tar.gz of a ROS 2 "
    "bag directory"
)


@dataclass(frozen=True)
class StoredUpload:
    key: str
    size: int
    sha256: str
    format: RecordingFormat


async def stream_to_storage(
    chunks: AsyncIterator[bytes],
    storage: Storage,
    key: str,
    *,
    max_bytes: int,
    declared_length: int | None,
    expected_sha256: str | None,
) -> StoredUpload:
    """Store the body under `key` if it passes every check; raise the matching problem if not."""
    if declared_length is not None and declared_length > max_bytes:
        raise UploadTooLarge(
            f"the body is {declared_length} bytes; the limit is {max_bytes}", limit=max_bytes
        )
    pending = await _run(storage.begin_upload, key)
    try:
        size, digest, found = await _receive(chunks, pending, max_bytes)
        if found is None:
            raise EmptyUpload(f"the body is empty; send the recording's bytes ({ACCEPTED})")
        if declared_length is not None and size != declared_length:
            raise ContentLengthMismatch(
                f"Content-Length said {declared_length} bytes but {size} arrived"
            )
        if expected_sha256 is not None and digest != expected_sha256.lower():
            raise ChecksumMismatch(
                f"X-Content-SHA256 is {expected_sha256.lower()} but the body "
                f"hashes to {digest}; the upload was damaged, send it again",
                received_sha256=digest,
            )
        await _run(pending.commit)
    except BaseException:
        with anyio.CancelScope(shield=True):
            await to_thread.run_sync(pending.abort)
        raise
    return StoredUpload(key=key, size=size, sha256=digest, format=found)


async def _receive(
    chunks: AsyncIterator[bytes], pending: PendingUpload, max_bytes: int
) -> tuple[int, str, RecordingFormat | None]:
    hasher = hashlib.sha256()
    block = bytearray()
    found: RecordingFormat | None = None
    size = 0

    def write(data: bytes) -> None:
        hasher.update(data)
        pending.write(data)

    try:
        async for chunk in chunks:
            size += len(chunk)
            if size > max_bytes:
                raise UploadTooLarge(
                    f"the body exceeds the limit of {max_bytes} bytes", limit=max_bytes
                )
            block += chunk
            if found is None and len(block) >= HEAD_BYTES:
                found = _check_head(bytes(block[:HEAD_BYTES]))
            if len(block) >= BLOCK_BYTES:
                data = bytes(block)
                block.clear()
                await _run(write, data)
    except ClientDisconnect as err:
        raise ClientDisconnected(
            f"the client closed the connection before the body was complete ({size} bytes arrived)"
        ) from err
    if found is None and size > 0:
        found = _check_head(bytes(block))
    if block:
        await _run(write, bytes(block))
    return size, hasher.hexdigest(), found


def _check_head(head: bytes) -> RecordingFormat:
    found = detect_format_from_head(head)
    if found is None:
        raise UnsupportedRecording(
            f"the body's first bytes match no recording format; accepted: {ACCEPTED}"
        )
    return found


async def _run(fn: Callable[P, T], *args: P.args, **kwargs: P.kwargs) -> T:
    """Run a (blocking) storage call in a worker thread."""
    return await to_thread.run_sync(lambda: fn(*args, **kwargs))
