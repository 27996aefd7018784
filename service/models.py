"""The database tables: robots, tolerance profiles, runs (also the job queue), results, per-LiDAR
extrinsics and API keys. Migrations in `migrations/versions` must match these (a test checks).
"""

from __future__ import annotations

import enum
import uuid
from datetime import UTC, datetime
from typing import Any, ClassVar

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    DateTime,
    Dialect,
    Enum,
    Float,
    ForeignKey,
    Index,
    Integer,
    MetaData,
    String,
    Text,
    TypeDecorator,
    UniqueConstraint,
    Uuid,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

from service.enums import DeliveryStatus, EventType, OverrideAction, RunKind, RunStatus, Scope

__all__ = [
    "ApiKey",
    "Base",
    "DeliveryStatus",
    "EventType",
    "LidarExtrinsic",
    "Override",
    "OverrideAction",
    "Result",
    "Robot",
    "Run",
    "RunKind",
    "RunStatus",
    "Scope",
    "ToleranceProfile",
    "UTCDateTime",
    "Webhook",
    "WebhookDelivery",
    "utcnow",
]

NAMING_CONVENTION = {
    "ix": "ix_%(table_name)s_%(column_0_N_name)s",
    "uq": "uq_%(table_name)s_%(column_0_N_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


def utcnow() -> datetime:
    return datetime.now(UTC)


class UTCDateTime(TypeDecorator[datetime]):
    """An aware UTC datetime on every database.

    PostgreSQL keeps `timestamptz`; SQLite has no time zones, so values are stored as naive UTC
    (fixed-width ISO text, which also sorts correctly) and made aware again when read.
    Naive values are refused: a local time slipping in would silently shift history.
    """

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        if value is None:
            return None
        if value.tzinfo is None:
            raise ValueError(f"naive datetime {value!r}: pass an aware (UTC) datetime")
        value = value.astimezone(UTC)
        return value.replace(tzinfo=None) if dialect.name == "sqlite" else value

    def process_result_value(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        if value is None:
            return None
        return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)


def _enum(cls: type[enum.StrEnum], name: str, length: int = 16) -> Enum:
    # VARCHAR + CHECK on both databases: no PostgreSQL enum type to migrate when a value is added.
    return Enum(
        cls,
        name=name,
        native_enum=False,
        create_constraint=True,
        length=length,
        values_callable=lambda members: [member.value for member in members],
        validate_strings=True,
    )


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING_CONVENTION)
    type_annotation_map: ClassVar[dict[Any, Any]] = {
        datetime: UTCDateTime(),
        dict[str, Any]: JSON(),
        list[str]: JSON(),
        uuid.UUID: Uuid(),
    }


class Robot(Base):
    """A robot of the fleet. Created by an admin or on its first upload."""

    __tablename__ = "robots"

    id: Mapped[str] = mapped_column(String(64), primary_key=True)
    model: Mapped[str | None] = mapped_column(String(64))
    # `metadata` is taken by SQLAlchemy's declarative base, hence the attribute name.
    meta: Mapped[dict[str, Any]] = mapped_column("metadata", JSON(), default=dict)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow, onupdate=utcnow)


class ToleranceProfile(Base):
    """Pass/fail limits for the robots of one model (or the default profile for any model)."""

    __tablename__ = "tolerance_profiles"

    name: Mapped[str] = mapped_column(String(64), primary_key=True)
    robot_model: Mapped[str | None] = mapped_column(String(64), unique=True)
    is_default: Mapped[bool] = mapped_column(Boolean, default=False)
    limits: Mapped[dict[str, Any]] = mapped_column(default=dict)
    design_extrinsics: Mapped[dict[str, Any] | None]
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow, onupdate=utcnow)


class Run(Base):
    """One uploaded recording and its calibration job; the runs table is the queue.

    A worker claims the oldest `queued` run whose `available_at` has passed (index `ix_runs_queue`),
    sets `lease_owner`/`lease_expires_at`, renews the lease by heartbeat, and writes the result and
    the final status in one transaction (`service.repository.store_result` / `fail_run`).
    """

    __tablename__ = "runs"
    __table_args__ = (
        UniqueConstraint("robot_id", "idempotency_key"),
        Index("ix_runs_queue", "status", "available_at"),
        Index("ix_runs_created", "created_at", "id"),
        Index("ix_runs_robot_created", "robot_id", "created_at", "id"),
        Index("ix_runs_status_created", "status", "created_at", "id"),
    )

    id: Mapped[uuid.UUID] = mapped_column(primary_key=True, default=uuid.uuid4)
    robot_id: Mapped[str] = mapped_column(ForeignKey("robots.id"))
    kind: Mapped[RunKind] = mapped_column(_enum(RunKind, "run_kind"))
    status: Mapped[RunStatus] = mapped_column(_enum(RunStatus, "run_status"))
    upload_size: Mapped[int] = mapped_column(BigInteger)
    upload_sha256: Mapped[str] = mapped_column(String(64))
    upload_format: Mapped[str] = mapped_column(String(16))
    storage_key: Mapped[str] = mapped_column(String(512))
    idempotency_key: Mapped[str | None] = mapped_column(String(255))
    config: Mapped[dict[str, Any] | None]
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    max_attempts: Mapped[int] = mapped_column(Integer)
    available_at: Mapped[datetime] = mapped_column(default=utcnow)
    lease_owner: Mapped[str | None] = mapped_column(String(255))
    lease_expires_at: Mapped[datetime | None]
    heartbeat_at: Mapped[datetime | None]
    stage: Mapped[str | None] = mapped_column(String(64))
    progress: Mapped[float | None] = mapped_column(Float)
    error: Mapped[dict[str, Any] | None]
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    started_at: Mapped[datetime | None]
    finished_at: Mapped[datetime | None]
    updated_at: Mapped[datetime] = mapped_column(default=utcnow, onupdate=utcnow)


class Result(Base):
    """The `result.json` of a run (at most one per run: the primary key is the run's id)."""

    __tablename__ = "results"
    __table_args__ = (
        Index("ix_results_robot_passed", "robot_id", "passed", "measured_at"),
        Index("ix_results_robot_accepted", "robot_id", "accepted", "measured_at"),
    )

    run_id: Mapped[uuid.UUID] = mapped_column(ForeignKey("runs.id"), primary_key=True)
    robot_id: Mapped[str] = mapped_column(ForeignKey("robots.id"))
    document: Mapped[dict[str, Any]]
    passed: Mapped[bool] = mapped_column(Boolean)
    # The verdict, unless an operator overrode it (`Override`): the calibration in use follows it.
    accepted: Mapped[bool] = mapped_column(Boolean)
    metric_error_initial: Mapped[float | None] = mapped_column(Float)
    metric_error_final: Mapped[float | None] = mapped_column(Float)
    pipeline_version: Mapped[str] = mapped_column(String(64))
    config_hash: Mapped[str | None] = mapped_column(String(80))
    # When the recording came in (the run's created_at): the time axis of history and "latest".
    measured_at: Mapped[datetime]
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class LidarExtrinsic(Base):
    """One LiDAR's calibrated `T_base_lidar` from one run: the rows behind drift plots."""

    __tablename__ = "lidar_extrinsics"
    __table_args__ = (
        UniqueConstraint("run_id", "frame"),
        Index("ix_lidar_extrinsics_robot_time", "robot_id", "measured_at", "id"),
        Index("ix_lidar_extrinsics_robot_frame_time", "robot_id", "frame", "measured_at", "id"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    run_id: Mapped[uuid.UUID] = mapped_column(ForeignKey("results.run_id"))
    robot_id: Mapped[str] = mapped_column(ForeignKey("robots.id"))
    frame: Mapped[str] = mapped_column(String(128))
    measured_at: Mapped[datetime]
    # Copied from the result's verdict (immutable once written) and its accepted flag (changed by
    # an override in the same transaction) so history can keep accepted ones without a join.
    passed: Mapped[bool] = mapped_column(Boolean)
    accepted: Mapped[bool] = mapped_column(Boolean)
    is_reference: Mapped[bool] = mapped_column(Boolean)
    tx: Mapped[float] = mapped_column(Float)
    ty: Mapped[float] = mapped_column(Float)
    tz: Mapped[float] = mapped_column(Float)
    qx: Mapped[float] = mapped_column(Float)
    qy: Mapped[float] = mapped_column(Float)
    qz: Mapped[float] = mapped_column(Float)
    qw: Mapped[float] = mapped_column(Float)
    stddev: Mapped[dict[str, Any] | None]


class ApiKey(Base):
    """An API key, stored as the sha256 of the secret; `id` is the public part of the key."""

    __tablename__ = "api_keys"

    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    key_hash: Mapped[str] = mapped_column(String(64))
    scopes: Mapped[list[str]]
    robot_id: Mapped[str | None] = mapped_column(String(64))
    name: Mapped[str | None] = mapped_column(String(255))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    revoked_at: Mapped[datetime | None]


class Override(Base):
    """An operator's accept or reject of a run's result: who, when and why (the audit trail)."""

    __tablename__ = "overrides"
    __table_args__ = (Index("ix_overrides_run_created", "run_id", "created_at"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    run_id: Mapped[uuid.UUID] = mapped_column(ForeignKey("results.run_id"))
    robot_id: Mapped[str] = mapped_column(ForeignKey("robots.id"))
    action: Mapped[OverrideAction] = mapped_column(_enum(OverrideAction, "override_action"))
    reason: Mapped[str] = mapped_column(String(1000))
    key_id: Mapped[str] = mapped_column(String(32))
    """The API key that made it (`api_keys.id`; kept when the key is revoked)."""
    key_name: Mapped[str | None] = mapped_column(String(255))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class Webhook(Base):
    """A URL an admin registered to be told of `events` (of robots of `robot_model`, if set)."""

    __tablename__ = "webhooks"

    id: Mapped[uuid.UUID] = mapped_column(primary_key=True, default=uuid.uuid4)
    url: Mapped[str] = mapped_column(String(2048))
    secret: Mapped[str] = mapped_column(String(128))
    """Signs each delivery (HMAC-SHA256 of the body); the receiver holds a copy, so not hashed."""
    events: Mapped[list[str]]
    robot_model: Mapped[str | None] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    deleted_at: Mapped[datetime | None]


class WebhookDelivery(Base):
    """The outbox: one row per event and webhook, written in the event's own transaction, sent
    by the workers (`workers.webhooks`) with a lease and backoff like a run."""

    __tablename__ = "webhook_deliveries"
    __table_args__ = (
        Index("ix_webhook_deliveries_due", "status", "available_at"),
        Index("ix_webhook_deliveries_webhook_created", "webhook_id", "created_at", "id"),
        UniqueConstraint("webhook_id", "event_id"),
    )

    id: Mapped[uuid.UUID] = mapped_column(primary_key=True, default=uuid.uuid4)
    webhook_id: Mapped[uuid.UUID] = mapped_column(ForeignKey("webhooks.id"))
    event_id: Mapped[uuid.UUID]
    """The same for every webhook told of one event: receivers drop duplicates by it."""
    event: Mapped[EventType] = mapped_column(_enum(EventType, "event_type", length=32))
    run_id: Mapped[uuid.UUID | None] = mapped_column(ForeignKey("runs.id"))
    robot_id: Mapped[str] = mapped_column(String(64))
    body: Mapped[str] = mapped_column(Text)
    """The exact bytes sent (UTF-8 JSON) and signed: every retry sends the same."""
    status: Mapped[DeliveryStatus] = mapped_column(_enum(DeliveryStatus, "delivery_status"))
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    max_attempts: Mapped[int] = mapped_column(Integer)
    available_at: Mapped[datetime] = mapped_column(default=utcnow)
    lease_owner: Mapped[str | None] = mapped_column(String(255))
    lease_expires_at: Mapped[datetime | None]
    last_status_code: Mapped[int | None] = mapped_column(Integer)
    last_error: Mapped[str | None] = mapped_column(String(1000))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    delivered_at: Mapped[datetime | None]
    updated_at: Mapped[datetime] = mapped_column(default=utcnow, onupdate=utcnow)
