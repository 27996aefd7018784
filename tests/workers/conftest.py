"""Fixtures for the worker tests: the service tests' databases (SQLite and PostgreSQL, one
PostgreSQL database per test session), plus queued runs and a quick way to make them."""

from __future__ import annotations

import uuid
from collections.abc import Iterator

import pytest

from service import repository
from service.db import Database
from service.models import RunKind
from service.settings import Settings

# The databases of every kind, as the service tests use them (imported to be registered here).
from tests.service.conftest import (  # noqa: F401
    db_url,
    pg_session_url,
    settings,
    sqlite_template,
)


@pytest.fixture
def db(settings: Settings) -> Iterator[Database]:  # noqa: F811 (the fixture)
    database = Database.from_settings(settings)
    yield database
    database.dispose()


def enqueue(
    db: Database,
    robot_id: str = "R1",
    *,
    kind: RunKind = RunKind.END_OF_LINE,
    storage_key: str | None = None,
    max_attempts: int = 3,
    config: dict[str, object] | None = None,
) -> uuid.UUID:
    """Record a queued run as the upload endpoint does (its recording need not exist)."""
    run_id = uuid.uuid4()
    upload = repository.NewUpload(
        run_id=run_id,
        robot_id=robot_id,
        kind=kind,
        size=1,
        sha256="0" * 64,
        format="mcap",
        storage_key=storage_key or f"recordings/{robot_id}/{run_id}",
        idempotency_key=None,
        config=config,
        max_attempts=max_attempts,
    )
    with db.transaction() as session:
        repository.record_upload(session, upload, create_robot=True)
    return run_id
