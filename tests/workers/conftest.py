"""Fixtures for the worker tests: the service tests' databases (SQLite and PostgreSQL, one
PostgreSQL database per test session) and a `Database` on them."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from service.db import Database
from service.settings import Settings

# The databases of every kind, as the service tests use them (imported to be registered here).
from tests.service.conftest import db_url, pg_session_url, s3_endpoint, sqlite_template  # noqa: F401


@pytest.fixture
def settings(db_url: str, tmp_path: Path) -> Settings:  # noqa: F811 (the fixture)
    """A migrated database of each kind and local storage; uploads up to 256 MiB (recordings)."""
    return Settings(
        data_dir=tmp_path / "data",
        database_url=db_url,
        storage_url=(tmp_path / "storage").as_uri(),
        max_upload_bytes=256 * 1024 * 1024,
        migrate_on_start=False,
    )


@pytest.fixture
def db(settings: Settings) -> Iterator[Database]:
    database = Database.from_settings(settings)
    yield database
    database.dispose()
