"""Fixtures for the reliability tests: the service tests' databases (SQLite and PostgreSQL, one
PostgreSQL database per test session), settings and running app, reused as they are."""

from __future__ import annotations

# Imported to be registered here as fixtures of this package.
from tests.service.conftest import (  # noqa: F401
    api,
    db_url,
    pg_session_url,
    settings,
    sqlite_template,
)
from tests.workers.test_end_to_end import tiny_recording  # noqa: F401
