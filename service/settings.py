"""The service's settings: one `Settings` object read from `FLEETCAL_*` environment variables.

Nothing is read at import; callers build `Settings()` (or `Settings(data_dir=...)` from a CLI
option) and hand it to `create_app`, `make_engine` and `make_storage`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated
from urllib.parse import urlsplit

from pydantic import Field, PositiveFloat, PositiveInt, ValidationInfo, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

DEFAULT_DATA_DIR = Path(".fleetcal")
"""Relative to the working directory, so a clone's demo keeps its state next to the code
(and `.gitignore` lists it); deployments set `FLEETCAL_DATA_DIR` or explicit URLs."""

GIB = 1024**3


class Settings(BaseSettings):
    """Service configuration. Every field can be set as `FLEETCAL_<FIELD>` in the environment.

    With nothing set, the service keeps a SQLite database (`fleetcal.db`) and a local object store
    (`storage/`) under `data_dir`, created on first use.
    """

    model_config = SettingsConfigDict(env_prefix="FLEETCAL_", extra="ignore", frozen=True)

    data_dir: Path = Field(
        default=DEFAULT_DATA_DIR,
        description="Directory of the embedded database and local storage (created on first use).",
    )
    database_url: str | None = Field(
        default=None,
        description="SQLAlchemy URL, e.g. postgresql+psycopg://user@host/db; "
        "default sqlite:///<data_dir>/fleetcal.db.",
    )
    storage_url: str | None = Field(
        default=None,
        description="file:///abs/dir or s3://bucket[/prefix]; default file://<data_dir>/storage.",
    )
    s3_endpoint_url: str | None = Field(
        default=None,
        description="Endpoint of an S3-compatible store (MinIO, Ceph, ...); unset for AWS. "
        "Credentials come from the usual AWS_* variables or profiles.",
    )
    s3_region: str | None = Field(default=None, description="Region of the S3 bucket.")
    s3_part_size_bytes: Annotated[int, Field(ge=5 * 1024**2)] = Field(
        default=16 * 1024**2,
        description="Multipart part size for S3 uploads (S3's minimum is 5 MiB); "
        "the memory one upload holds at most.",
    )
    max_upload_bytes: PositiveInt = Field(
        default=8 * GIB,
        description="Largest recording accepted (413 past it).",
    )
    create_robots_on_upload: bool = Field(
        default=True,
        description="Register an unknown robot on its first upload (by a key allowed to upload "
        "for it); when false, uploads for unknown robots get 404.",
    )
    migrate_on_start: bool = Field(
        default=True, description="Apply pending Alembic migrations when the API starts."
    )
    run_max_attempts: PositiveInt = Field(
        default=3, description="Attempts a run gets before the queue marks it failed."
    )
    run_lease_seconds: PositiveInt = Field(
        default=60, description="How long a worker's claim on a run lasts without a heartbeat."
    )
    webhook_timeout_seconds: PositiveFloat = Field(
        default=10.0, description="How long a webhook receiver may take to answer a delivery."
    )
    webhook_backoff_seconds: PositiveFloat = Field(
        default=2.0,
        description="Wait before a failed webhook delivery's second try; it doubles each try "
        "(up to 30 min).",
    )
    webhook_lease_seconds: PositiveInt = Field(
        default=120,
        description="How long a worker holds a webhook delivery it is sending; one killed "
        "meanwhile leaves it to be sent again after this.",
    )
    sqlite_busy_timeout_ms: PositiveInt = Field(
        default=30_000, description="How long a SQLite writer waits for the lock before failing."
    )
    stale_upload_seconds: PositiveInt = Field(
        default=6 * 3600,
        description="At start, S3 multipart uploads begun this long ago are taken for left-overs "
        "of a killed process and aborted (other API processes may be uploading). Local partial "
        "uploads go at once when no process holds their lock, locked ones after this long.",
    )

    @field_validator("database_url", "storage_url", "s3_endpoint_url", mode="before")
    @classmethod
    def _empty_is_unset(cls, value: object) -> object:
        return None if value == "" else value

    @field_validator("database_url", "storage_url")
    @classmethod
    def _a_supported_url(cls, value: str | None, info: ValidationInfo) -> str | None:
        if value is not None:
            check = check_database_url if info.field_name == "database_url" else check_storage_url
            check(value)
        return value

    @property
    def resolved_database_url(self) -> str:
        if self.database_url:
            return self.database_url
        return f"sqlite:///{(self.data_dir / 'fleetcal.db').resolve()}"

    @property
    def resolved_storage_url(self) -> str:
        if self.storage_url:
            return self.storage_url
        return (self.data_dir / "storage").resolve().as_uri()


SUPPORTED_DATABASES = ("sqlite", "postgresql")
"""The queue needs `BEGIN IMMEDIATE` (SQLite) or `FOR UPDATE SKIP LOCKED` (PostgreSQL)."""


def check_database_url(url: str) -> None:
    """Raise `ValueError` saying what to write if `url` is no SQLAlchemy URL of a supported
    database whose driver is installed. Nothing is connected to."""
    from sqlalchemy import make_url
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError

    example = "sqlite:////abs/path/fleetcal.db or postgresql+psycopg://user:password@host/db"
    try:
        parsed = make_url(url)
    except ArgumentError:
        raise ValueError(f"{url!r} is not a database URL; use {example}") from None
    shown = parsed.render_as_string(hide_password=True)
    if parsed.get_backend_name() not in SUPPORTED_DATABASES:
        raise ValueError(
            f"{shown!r} names the database {parsed.get_backend_name()!r}; fleetcal runs on "
            f"SQLite or PostgreSQL: use {example}"
        )
    try:
        parsed.get_dialect()
    except NoSuchModuleError:
        raise ValueError(
            f"{shown!r} names the driver {parsed.get_driver_name()!r}, which is not installed; "
            f"use {example}"
        ) from None


def check_storage_url(url: str) -> None:
    """Raise `ValueError` saying what to write if `url` is no storage URL fleetcal can use."""
    parts = urlsplit(url)
    if parts.scheme == "file" and parts.path.startswith("/"):
        return
    if parts.scheme == "s3" and parts.netloc:
        return
    raise ValueError(
        f"unsupported storage URL {url!r}: use file:///absolute/dir or s3://bucket[/prefix]"
    )
