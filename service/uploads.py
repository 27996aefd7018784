"""Streaming a request body into storage: size limit, SHA-256 on the fly, magic-byte check.

The body is never held whole: chunks gather into blocks of about `BLOCK_BYTES`, and each block is
hashed and written in a worker thread (hashlib and file writes release the GIL) while the event
loop receives the next one, so at most two blocks are held at a time. On any failure, disconnect
included, the pending object is aborted: nothing partial survives. Storage errors propagate as
`StorageError`; `service.problem_details` maps them (503, or 507 when full).
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
from collections.abc import AsyncIterator
from dataclasses import dataclass

import anyio
from anyio import to_thread
from starlette.requests import ClientDisconnect

from pipeline.io import HEAD_BYTES, RecordingFormat, detect_format_from_head
from service.problem_details import (
    ChecksumMismatch,
    ClientDisconnected,
    ContentLengthMismatch,
    EmptyUpload,
    UnsupportedRecording,
    UploadTooLarge,
)
from service.storage import PendingUpload, Storage

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
    pending = await to_thread.run_sync(storage.begin_upload, key)
    try:
        sink = _Sink(pending)
        found = await sink.receive(chunks, max_bytes)
        if found is None:
            raise EmptyUpload(f"the body is empty; send the recording's bytes ({ACCEPTED})")
        if declared_length is not None and sink.size != declared_length:
            raise ContentLengthMismatch(
                f"Content-Length said {declared_length} bytes but {sink.size} arrived"
            )
        digest = sink.hasher.hexdigest()
        if expected_sha256 is not None and digest != expected_sha256.lower():
            raise ChecksumMismatch(
                f"X-Content-SHA256 is {expected_sha256.lower()} but the body hashes to {digest}; "
                "the upload was damaged, send it again",
                received_sha256=digest,
            )
        await to_thread.run_sync(pending.commit)
    except BaseException:
        with anyio.CancelScope(shield=True):
            await to_thread.run_sync(pending.abort)
        raise
    return StoredUpload(key=key, size=sink.size, sha256=digest, format=found)


class _Sink:
    """Hashes and writes blocks one step behind the receiving loop."""

    def __init__(self, pending: PendingUpload) -> None:
        self.pending = pending
        self.hasher = hashlib.sha256()
        self.size = 0
        self._in_flight: asyncio.Future[None] | None = None

    def _write(self, pieces: list[bytes]) -> None:
        for piece in pieces:  # no joining: each piece is hashed and written as it came
            self.hasher.update(piece)
            self.pending.write(piece)

    async def _hand_over(self, pieces: list[bytes]) -> None:
        await self._settle()
        loop = asyncio.get_running_loop()
        self._in_flight = loop.run_in_executor(None, self._write, pieces)

    async def _settle(self) -> None:
        if self._in_flight is not None:
            in_flight, self._in_flight = self._in_flight, None
            await in_flight

    async def receive(self, chunks: AsyncIterator[bytes], max_bytes: int) -> RecordingFormat | None:
        block: list[bytes] = []
        block_size = 0
        found: RecordingFormat | None = None
        try:
            async for chunk in chunks:
                self.size += len(chunk)
                if self.size > max_bytes:
                    raise UploadTooLarge(
                        f"the body exceeds the limit of {max_bytes} bytes", limit=max_bytes
                    )
                block.append(chunk)
                block_size += len(chunk)
                if found is None and self.size >= HEAD_BYTES:
                    found = _check_head(b"".join(block)[:HEAD_BYTES])
                if block_size >= BLOCK_BYTES:
                    await self._hand_over(block)
                    block, block_size = [], 0
            if found is None and self.size > 0:
                found = _check_head(b"".join(block))
            if block:
                await self._hand_over(block)
            await self._settle()
        except ClientDisconnect as err:
            raise ClientDisconnected(
                "the client closed the connection before the body was complete "
                f"({self.size} bytes arrived)"
            ) from err
        finally:
            # Never abort under a write still running in its thread.
            with anyio.CancelScope(shield=True), contextlib.suppress(Exception):
                await self._settle()
        return found


def _check_head(head: bytes) -> RecordingFormat:
    found = detect_format_from_head(head)
    if found is None:
        raise UnsupportedRecording(
            f"the body's first bytes match no recording format; accepted: {ACCEPTED}"
        )
    return found
