"""The service's vocabularies (run kinds and states, key scopes), free of heavy imports so that
the CLI can offer them as choices without loading SQLAlchemy."""

from __future__ import annotations

import enum


class RunKind(enum.StrEnum):
    END_OF_LINE = "end_of_line"
    MAINTENANCE = "maintenance"


class RunStatus(enum.StrEnum):
    QUEUED = "queued"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"


class Scope(enum.StrEnum):
    UPLOAD = "upload"
    READ = "read"
    ADMIN = "admin"
