"""Initial schema: robots, tolerance profiles, runs (the queue), results, extrinsics, API keys.

Revision ID: 0001
Revises:
Create Date: 2026-11-22
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0001"
down_revision: str | None = None
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

# Frozen copies of the model types: a migration must not change when the models do.
UTC_DATETIME = sa.DateTime(timezone=True)


def _enum(name: str, *values: str) -> sa.Enum:
    return sa.Enum(*values, name=name, native_enum=False, create_constraint=True, length=16)


def upgrade() -> None:
    op.create_table(
        "api_keys",
        sa.Column("id", sa.String(length=32), nullable=False),
        sa.Column("key_hash", sa.String(length=64), nullable=False),
        sa.Column("scopes", sa.JSON(), nullable=False),
        sa.Column("robot_id", sa.String(length=64), nullable=True),
        sa.Column("name", sa.String(length=255), nullable=True),
        sa.Column("created_at", UTC_DATETIME, nullable=False),
        sa.Column("revoked_at", UTC_DATETIME, nullable=True),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_api_keys")),
    )
    op.create_table(
        "robots",
        sa.Column("id", sa.String(length=64), nullable=False),
        sa.Column("model", sa.String(length=64), nullable=True),
        sa.Column("metadata", sa.JSON(), nullable=False),
        sa.Column("created_at", UTC_DATETIME, nullable=False),
        sa.Column("updated_at", UTC_DATETIME, nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_robots")),
    )
    op.create_table(
        "tolerance_profiles",
        sa.Column("name", sa.String(length=64), nullable=False),
        sa.Column("robot_model", sa.String(length=64), nullable=True),
        sa.Column("is_default", sa.Boolean(), nullable=False),
        sa.Column("limits", sa.JSON(), nullable=False),
        sa.Column("design_extrinsics", sa.JSON(), nullable=True),
        sa.Column("created_at", UTC_DATETIME, nullable=False),
        sa.Column("updated_at", UTC_DATETIME, nullable=False),
        sa.PrimaryKeyConstraint("name", name=op.f("pk_tolerance_profiles")),
        sa.UniqueConstraint("robot_model", name=op.f("uq_tolerance_profiles_robot_model")),
    )
    op.create_table(
        "runs",
        sa.Column("id", sa.Uuid(), nullable=False),
        sa.Column("robot_id", sa.String(length=64), nullable=False),
        sa.Column("kind", _enum("run_kind", "end_of_line", "maintenance"), nullable=False),
        sa.Column(
            "status",
            _enum("run_status", "queued", "running", "succeeded", "failed"),
            nullable=False,
        ),
        sa.Column("upload_size", sa.BigInteger(), nullable=False),
        sa.Column("upload_sha256", sa.String(length=64), nullable=False),
        sa.Column("upload_format", sa.String(length=16), nullable=False),
        sa.Column("storage_key", sa.String(length=512), nullable=False),
        sa.Column("idempotency_key", sa.String(length=255), nullable=True),
        sa.Column("config", sa.JSON(), nullable=True),
        sa.Column("attempts", sa.Integer(), nullable=False),
        sa.Column("max_attempts", sa.Integer(), nullable=False),
        sa.Column("available_at", UTC_DATETIME, nullable=False),
        sa.Column("lease_owner", sa.String(length=255), nullable=True),
        sa.Column("lease_expires_at", UTC_DATETIME, nullable=True),
        sa.Column("heartbeat_at", UTC_DATETIME, nullable=True),
        sa.Column("stage", sa.String(length=64), nullable=True),
        sa.Column("progress", sa.Float(), nullable=True),
        sa.Column("error", sa.JSON(), nullable=True),
        sa.Column("created_at", UTC_DATETIME, nullable=False),
        sa.Column("started_at", UTC_DATETIME, nullable=True),
        sa.Column("finished_at", UTC_DATETIME, nullable=True),
        sa.Column("updated_at", UTC_DATETIME, nullable=False),
        sa.ForeignKeyConstraint(["robot_id"], ["robots.id"], name=op.f("fk_runs_robot_id_robots")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_runs")),
        sa.UniqueConstraint(
            "robot_id", "idempotency_key", name=op.f("uq_runs_robot_id_idempotency_key")
        ),
    )
    op.create_index("ix_runs_created", "runs", ["created_at", "id"])
    op.create_index("ix_runs_queue", "runs", ["status", "available_at"])
    op.create_index("ix_runs_robot_created", "runs", ["robot_id", "created_at", "id"])
    op.create_index("ix_runs_status_created", "runs", ["status", "created_at", "id"])
    op.create_table(
        "results",
        sa.Column("run_id", sa.Uuid(), nullable=False),
        sa.Column("robot_id", sa.String(length=64), nullable=False),
        sa.Column("document", sa.JSON(), nullable=False),
        sa.Column("passed", sa.Boolean(), nullable=False),
        sa.Column("metric_error_initial", sa.Float(), nullable=True),
        sa.Column("metric_error_final", sa.Float(), nullable=True),
        sa.Column("pipeline_version", sa.String(length=64), nullable=False),
        sa.Column("config_hash", sa.String(length=80), nullable=True),
        sa.Column("measured_at", UTC_DATETIME, nullable=False),
        sa.Column("created_at", UTC_DATETIME, nullable=False),
        sa.ForeignKeyConstraint(
            ["robot_id"], ["robots.id"], name=op.f("fk_results_robot_id_robots")
        ),
        sa.ForeignKeyConstraint(["run_id"], ["runs.id"], name=op.f("fk_results_run_id_runs")),
        sa.PrimaryKeyConstraint("run_id", name=op.f("pk_results")),
    )
    op.create_index("ix_results_robot_passed", "results", ["robot_id", "passed", "measured_at"])
    op.create_table(
        "lidar_extrinsics",
        sa.Column("id", sa.Integer(), autoincrement=True, nullable=False),
        sa.Column("run_id", sa.Uuid(), nullable=False),
        sa.Column("robot_id", sa.String(length=64), nullable=False),
        sa.Column("frame", sa.String(length=128), nullable=False),
        sa.Column("measured_at", UTC_DATETIME, nullable=False),
        sa.Column("passed", sa.Boolean(), nullable=False),
        sa.Column("is_reference", sa.Boolean(), nullable=False),
        sa.Column("tx", sa.Float(), nullable=False),
        sa.Column("ty", sa.Float(), nullable=False),
        sa.Column("tz", sa.Float(), nullable=False),
        sa.Column("qx", sa.Float(), nullable=False),
        sa.Column("qy", sa.Float(), nullable=False),
        sa.Column("qz", sa.Float(), nullable=False),
        sa.Column("qw", sa.Float(), nullable=False),
        sa.Column("stddev", sa.JSON(), nullable=True),
        sa.ForeignKeyConstraint(
            ["robot_id"], ["robots.id"], name=op.f("fk_lidar_extrinsics_robot_id_robots")
        ),
        sa.ForeignKeyConstraint(
            ["run_id"], ["results.run_id"], name=op.f("fk_lidar_extrinsics_run_id_results")
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_lidar_extrinsics")),
        sa.UniqueConstraint("run_id", "frame", name=op.f("uq_lidar_extrinsics_run_id_frame")),
    )
    op.create_index(
        "ix_lidar_extrinsics_robot_frame_time",
        "lidar_extrinsics",
        ["robot_id", "frame", "measured_at", "id"],
    )
    op.create_index(
        "ix_lidar_extrinsics_robot_time", "lidar_extrinsics", ["robot_id", "measured_at", "id"]
    )


def downgrade() -> None:
    op.drop_index("ix_lidar_extrinsics_robot_time", table_name="lidar_extrinsics")
    op.drop_index("ix_lidar_extrinsics_robot_frame_time", table_name="lidar_extrinsics")
    op.drop_table("lidar_extrinsics")
    op.drop_index("ix_results_robot_passed", table_name="results")
    op.drop_table("results")
    op.drop_index("ix_runs_status_created", table_name="runs")
    op.drop_index("ix_runs_robot_created", table_name="runs")
    op.drop_index("ix_runs_queue", table_name="runs")
    op.drop_index("ix_runs_created", table_name="runs")
    op.drop_table("runs")
    op.drop_table("tolerance_profiles")
    op.drop_table("robots")
    op.drop_table("api_keys")
