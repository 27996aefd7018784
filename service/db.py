"""Engines, sessions, migrations: `make_engine(settings)` and `Database`; nothing built at import.

SQLite runs with foreign keys on, WAL, a busy timeout, and explicit `BEGIN` so that writers can ask
for `BEGIN IMMEDIATE` (a deferred transaction that reads and then writes can fail with "database is
locked" without waiting; an immediate one waits its turn).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from functools import cached_property
from pathlib import Path
from typing import Any

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import Connection, Engine, create_engine, event, make_url, text
from sqlalchemy.orm import Session, sessionmaker

from service.settings import Settings

MIGRATIONS_DIR = Path(__file__).resolve().parent.parent / "migrations"
SQLITE_BEGIN_OPTION = "fleetcal_sqlite_begin"
"""Execution option naming the SQLite transaction mode: "DEFERRED" (default) or "IMMEDIATE"."""
_PG_MIGRATION_LOCK = (
    0x666C6565  # pg_advisory_lock key: API processes starting together migrate once
)


def make_engine(settings: Settings) -> Engine:
    """The engine for `settings.resolved_database_url`; creates the SQLite file's directory."""
    url = make_url(settings.resolved_database_url)
    if url.get_backend_name() != "sqlite":
        return create_engine(url, pool_pre_ping=True, pool_size=10, max_overflow=20)
    if url.database and url.database != ":memory:":
        Path(url.database).parent.mkdir(parents=True, exist_ok=True)
    engine = create_engine(url, connect_args={"check_same_thread": False})
    busy_timeout_ms = settings.sqlite_busy_timeout_ms

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_connection: Any, _record: Any) -> None:
        # Let SQLAlchemy, not the sqlite3 module, decide when transactions begin.
        dbapi_connection.isolation_level = None
        cursor = dbapi_connection.cursor()
        cursor.execute("PRAGMA foreign_keys = ON")
        cursor.execute(f"PRAGMA busy_timeout = {int(busy_timeout_ms)}")
        cursor.execute("PRAGMA journal_mode = WAL")
        cursor.execute("PRAGMA synchronous = NORMAL")
        cursor.close()

    @event.listens_for(engine, "begin")
    def _on_begin(connection: Connection) -> None:
        mode = connection.get_execution_options().get(SQLITE_BEGIN_OPTION, "DEFERRED")
        if mode not in ("DEFERRED", "IMMEDIATE"):
            raise ValueError(f"{SQLITE_BEGIN_OPTION} must be DEFERRED or IMMEDIATE, not {mode!r}")
        connection.exec_driver_sql(f"BEGIN {mode}")

    return engine


class Database:
    """An engine with its two session factories: `session()` for reads, `write_session()` for
    transactions that write (on SQLite they take the write lock up front with `BEGIN IMMEDIATE`)."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine
        self._sessions = sessionmaker(engine, expire_on_commit=False)
        self._write_sessions = sessionmaker(
            engine.execution_options(**{SQLITE_BEGIN_OPTION: "IMMEDIATE"}),
            expire_on_commit=False,
        )

    @classmethod
    def from_settings(cls, settings: Settings) -> Database:
        return cls(make_engine(settings))

    @property
    def is_sqlite(self) -> bool:
        return self.engine.dialect.name == "sqlite"

    def session(self) -> Session:
        return self._sessions()

    def write_session(self) -> Session:
        return self._write_sessions()

    @contextmanager
    def transaction(self) -> Iterator[Session]:
        """A write session inside one transaction: committed on success, rolled back on error."""
        with self.write_session() as session, session.begin():
            yield session

    def dispose(self) -> None:
        self.engine.dispose()

    # -- migrations -------------------------------------------------------------------------------

    @cached_property
    def _alembic_config(self) -> Config:
        return alembic_config()

    def upgrade(self, revision: str = "head") -> None:
        """Apply migrations up to `revision`; safe when several processes start at once."""
        with self.engine.connect() as connection:
            if connection.dialect.name == "postgresql":
                connection.execute(
                    text("SELECT pg_advisory_lock(:key)"), {"key": _PG_MIGRATION_LOCK}
                )
                connection.commit()
                try:
                    self._run(command.upgrade, connection, revision)
                finally:
                    connection.execute(
                        text("SELECT pg_advisory_unlock(:key)"), {"key": _PG_MIGRATION_LOCK}
                    )
                    connection.commit()
            else:
                self._run(command.upgrade, connection, revision)

    def downgrade(self, revision: str) -> None:
        with self.engine.connect() as connection:
            self._run(command.downgrade, connection, revision)

    def _run(self, fn: Any, connection: Connection, revision: str) -> None:
        config = self._alembic_config
        config.attributes["connection"] = connection
        try:
            fn(config, revision)
            connection.commit()
        finally:
            config.attributes.pop("connection", None)

    def current_revisions(self) -> set[str]:
        with self.engine.connect() as connection:
            return set(MigrationContext.configure(connection).get_current_heads())

    def head_revisions(self) -> set[str]:
        return set(self._heads)

    @cached_property
    def _heads(self) -> frozenset[str]:
        # The scripts do not change while the process runs; parse them once.
        return frozenset(ScriptDirectory.from_config(self._alembic_config).get_heads())

    def migrations_current(self) -> bool:
        return self.current_revisions() == self.head_revisions()


def alembic_config() -> Config:
    """Alembic's configuration, built here rather than read from a top-level `alembic.ini`."""
    config = Config(str(MIGRATIONS_DIR / "alembic.ini"))
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    return config
