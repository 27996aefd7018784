"""`NewUpload`s for tests that put runs in the database without going through the API."""

from __future__ import annotations

import hashlib
import uuid
from typing import Any

from service import repository
from service.models import RunKind


def new_upload(
    robot_id: str = "R1",
    *,
    run_id: uuid.UUID | None = None,
    kind: RunKind = RunKind.END_OF_LINE,
    body: bytes | None = None,
    size: int = 1,
    storage_key: str | None = None,
    idempotency_key: str | None = None,
    config: dict[str, Any] | None = None,
    max_attempts: int = 3,
    format: str = "mcap",
) -> repository.NewUpload:
    """A queued run's upload: `body` (when given) sets its size and digest, else `size` and a zero
    digest; the storage key is the run's usual one unless given."""
    run_id = run_id or uuid.uuid4()
    return repository.NewUpload(
        run_id=run_id,
        robot_id=robot_id,
        kind=kind,
        size=len(body) if body is not None else size,
        sha256=hashlib.sha256(body).hexdigest() if body is not None else "0" * 64,
        format=format,
        storage_key=storage_key or repository.recording_key(robot_id, run_id),
        idempotency_key=idempotency_key,
        config=config,
        max_attempts=max_attempts,
    )
