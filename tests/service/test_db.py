"""Engine settings: SQLite pragmas, `BEGIN IMMEDIATE` writers; UTC timestamps on both databases."""

from __future__ import annotations

import sqlite3
import uuid
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path

import pytest
from sqlalchemy import select, text
from sqlalchemy.exc import IntegrityError, StatementError

from service.db import Database
from service.models import Robot
from service.settings import Settings


def test_sqlite_connections_have_foreign_keys_wal_and_busy_timeout(tmp_path: Path) -> None:
    db = Database.from_settings(
        Settings(data_dir=tmp_path / "nested" / "dir", sqlite_busy_timeout_ms=1234)
    )
    with db.session() as session:
        assert session.scalar(text("PRAGMA foreign_keys")) == 1
        assert session.scalar(text("PRAGMA journal_mode")) == "wal"
        assert session.scalar(text("PRAGMA busy_timeout")) == 1234
    assert (tmp_path / "nested" / "dir" / "fleetcal.db").is_file()
    db.dispose()


def test_sqlite_write_session_takes_the_write_lock_up_front(tmp_path: Path) -> None:
    db = Database.from_settings(Settings(data_dir=tmp_path))
    db.upgrade()
    with db.write_session() as writer:
        writer.execute(select(Robot))  # only a read, but BEGIN IMMEDIATE already holds the lock
        other = sqlite3.connect(tmp_path / "fleetcal.db", timeout=0.05, isolation_level=None)
        with pytest.raises(sqlite3.OperationalError, match="locked"):
            other.execute("BEGIN IMMEDIATE")
        other.close()
    with db.session() as reader:
        reader.execute(select(Robot))  # a deferred reader takes no lock
        other = sqlite3.connect(tmp_path / "fleetcal.db", timeout=0.05, isolation_level=None)
        other.execute("BEGIN IMMEDIATE")
        other.execute("ROLLBACK")
        other.close()
    db.dispose()


def test_foreign_keys_are_enforced(settings: Settings) -> None:
    db = Database.from_settings(settings)
    with pytest.raises(IntegrityError), db.transaction() as session:
        session.execute(
            text(
                "INSERT INTO results (run_id, robot_id, document, passed, pipeline_version, "
                "measured_at, created_at) VALUES (:run, 'nobody', '{}', true, 'x', :t, :t)"
            ),
            {"run": uuid.uuid4().hex, "t": datetime.now(UTC)},
        )
    db.dispose()


def test_timestamps_round_trip_as_aware_utc(settings: Settings) -> None:
    db = Database.from_settings(settings)
    local = datetime(2026, 3, 1, 14, 30, 15, 123456, tzinfo=timezone(timedelta(hours=2)))
    with db.transaction() as session:
        session.add(Robot(id="R1", meta={}, created_at=local, updated_at=local))
    with db.session() as session:
        robot = session.get(Robot, "R1")
        assert robot is not None
        assert robot.created_at.tzinfo == UTC
        assert robot.created_at == local
        assert robot.created_at.hour == 12 and robot.created_at.microsecond == 123456
        # Comparisons in SQL see the same instant.
        assert session.scalar(select(Robot.id).where(Robot.created_at == local)) == "R1"
        assert session.scalar(select(Robot.id).where(Robot.created_at > local)) is None
    db.dispose()


def test_naive_timestamps_are_refused(settings: Settings) -> None:
    db = Database.from_settings(settings)
    with pytest.raises(StatementError, match="naive datetime"), db.transaction() as session:
        session.add(Robot(id="R1", meta={}, created_at=datetime(2026, 1, 1)))
    db.dispose()
