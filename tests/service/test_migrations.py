"""Migrations: upgrade, downgrade and upgrade again on both databases, and no drift between the
models and the migrations (Alembic's autogenerate comparison finds nothing to add)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import Column, Integer, MetaData, inspect

from service.db import Database
from service.models import Base
from service.settings import Settings
from tests.service.conftest import scratch_pg_database


@pytest.fixture(params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def empty_db(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Database]:
    if request.param == "sqlite":
        db = Database.from_settings(Settings(database_url=f"sqlite:///{tmp_path / 'm.db'}"))
        yield db
        db.dispose()
        return
    with scratch_pg_database() as url:
        db = Database.from_settings(Settings(database_url=url))
        yield db
        db.dispose()


def _diff(db: Database, metadata: MetaData) -> list[object]:
    with db.engine.connect() as connection:
        context = MigrationContext.configure(connection, opts={"compare_type": True})
        return list(compare_metadata(context, metadata))


def test_upgrade_downgrade_upgrade_round_trip(empty_db: Database) -> None:
    tables = {t.name for t in Base.metadata.sorted_tables}
    empty_db.upgrade()
    assert tables <= set(inspect(empty_db.engine).get_table_names())
    assert empty_db.migrations_current()

    empty_db.downgrade("base")
    assert not tables & set(inspect(empty_db.engine).get_table_names())
    assert empty_db.current_revisions() == set()
    assert not empty_db.migrations_current()

    empty_db.upgrade()
    assert tables <= set(inspect(empty_db.engine).get_table_names())
    assert empty_db.migrations_current()


def test_models_match_migrations(empty_db: Database) -> None:
    empty_db.upgrade()
    assert _diff(empty_db, Base.metadata) == []


def test_drift_check_sees_a_column_the_migrations_lack(empty_db: Database) -> None:
    # The negative control: the comparison above would fail if a model changed unmigrated.
    empty_db.upgrade()
    drifted = MetaData(naming_convention=Base.metadata.naming_convention)
    for table in Base.metadata.sorted_tables:
        table.to_metadata(drifted)
    drifted.tables["runs"].append_column(Column("priority", Integer, nullable=True))
    diff = _diff(empty_db, drifted)
    assert [(op[0], op[3].name) for op in diff] == [("add_column", "priority")]  # type: ignore[index]


def test_upgrade_twice_is_a_no_op(empty_db: Database) -> None:
    empty_db.upgrade()
    empty_db.upgrade()
    assert empty_db.current_revisions() == empty_db.head_revisions()
