"""Fixtures for the worker tests: the service tests' databases (SQLite and PostgreSQL, one
PostgreSQL database per test session) and a `Database` on them."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from service.db import Database
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
