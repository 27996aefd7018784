"""The service's vocabularies (run kinds and states, key scopes, webhook events, overrides), free
of heavy imports so that the CLI can offer them as choices without loading SQLAlchemy."""

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
    OVERRIDE = "override"
    """Accept a failed calibration or reject a passed one (an operator's call, audited)."""
    ADMIN = "admin"


class EventType(enum.StrEnum):
    """What a webhook can be told about (`service.outbox`)."""

    RUN_FINISHED = "run.finished"
    """A run stored its result (passed or not)."""
    VERDICT_FAILED = "verdict.failed"
    """A run's result did not pass its checks."""
    DRIFT_EXCEEDED = "drift.exceeded"
    """A maintenance run moved past the profile's drift limit from the last accepted calibration."""
    RUN_FAILED = "run.failed"
    """A run ended without a result after its attempts."""


class DeliveryStatus(enum.StrEnum):
    PENDING = "pending"
    DELIVERED = "delivered"
    FAILED = "failed"


class OverrideAction(enum.StrEnum):
    ACCEPT = "accept"
    REJECT = "reject"
