"""Migrations: upgrade, downgrade and upgrade again on both databases, and no drift between the
models and the migrations (Alembic's autogenerate comparison finds nothing to add)."""

from __future__ import annotations

from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import Column, Integer, MetaData, inspect

from service.db import Database
from service.models import Base


def _diff(db: Database, metadata: MetaData) -> list[object]:
    with db.engine.connect() as connection:
        context = MigrationContext.configure(connection, opts={"compare_type": True})
        return list(compare_metadata(context, metadata))


def test_upgrade_downgrade_upgrade_round_trip(unmigrated_db: Database) -> None:
    tables = {t.name for t in Base.metadata.sorted_tables}
    unmigrated_db.upgrade()
    assert tables <= set(inspect(unmigrated_db.engine).get_table_names())
    assert unmigrated_db.migrations_current()

    unmigrated_db.downgrade("base")
    assert not tables & set(inspect(unmigrated_db.engine).get_table_names())
    assert unmigrated_db.current_revisions() == set()
    assert not unmigrated_db.migrations_current()

    unmigrated_db.upgrade()
    assert tables <= set(inspect(unmigrated_db.engine).get_table_names())
    assert unmigrated_db.migrations_current()


def test_models_match_migrations(unmigrated_db: Database) -> None:
    unmigrated_db.upgrade()
    assert _diff(unmigrated_db, Base.metadata) == []


def test_drift_check_sees_a_column_the_migrations_lack(unmigrated_db: Database) -> None:
    # The negative control: the comparison above would fail if a model changed unmigrated.
    unmigrated_db.upgrade()
    drifted = MetaData(naming_convention=Base.metadata.naming_convention)
    for table in Base.metadata.sorted_tables:
        table.to_metadata(drifted)
    drifted.tables["runs"].append_column(Column("priority", Integer, nullable=True))
    diff = _diff(unmigrated_db, drifted)
    assert [(op[0], op[3].name) for op in diff] == [("add_column", "priority")]  # type: ignore[index]


def test_upgrade_twice_is_a_no_op(unmigrated_db: Database) -> None:
    unmigrated_db.upgrade()
    unmigrated_db.upgrade()
    assert unmigrated_db.current_revisions() == unmigrated_db.head_revisions()
