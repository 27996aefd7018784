"""The retry policy, in one place: which failures of an attempt are retried (with backoff) and which
fail the run at once, and the problem document (RFC 9457) a failed run keeps in `runs.error`.

Like Oban and River, every failure we cannot prove permanent is retried until the run's
`max_attempts` is used up; only `pipeline.errors.BadInputError` (the same input gives the same
error) fails a run at its first attempt.
"""

from __future__ import annotations

import enum
import random
import re
from dataclasses import dataclass
from datetime import timedelta
from typing import Any

from pipeline import BadInputError, ConfigError
from service.problem_details import problem_document
from service.storage import StorageError


class FailureKind(enum.StrEnum):
    BAD_INPUT = "bad_input"
    """The recording or its config cannot be calibrated; retrying gives the same error."""
    TRANSIENT = "transient"
    """Storage or database trouble, or the machine's resources: worth another try later."""
    UNEXPECTED = "unexpected"
    """Any other exception (a bug, most likely); retried in case it was the machine's fault."""
    CRASH = "crash"
    """The process running the pipeline died (killed, out of memory, segfault)."""
    TIMEOUT = "timeout"
    """The attempt ran longer than the worker's run timeout and was stopped."""
    LOST = "lost"
    """The worker holding the run stopped renewing its lease (killed, or cut off)."""


@dataclass(frozen=True)
class Failure:
    """What went wrong in one attempt, in a form that crosses process boundaries (pickles)."""

    kind: FailureKind
    message: str
    error_type: str | None = None
    stage: str | None = None


@dataclass(frozen=True)
class RetryPolicy:
    """Backoff before attempt n+1: `base * 2**(n-1)` capped at `cap`, with +-20 % jitter so that
    runs that failed together (a storage outage) do not come back together."""

    backoff_base: timedelta = timedelta(seconds=5)
    backoff_cap: timedelta = timedelta(minutes=5)
    jitter: float = 0.2

    def backoff(self, attempts: int) -> timedelta:
        seconds = min(
            self.backoff_base.total_seconds() * 2 ** max(attempts - 1, 0),
            self.backoff_cap.total_seconds(),
        )
        return timedelta(seconds=seconds * (1 + self.jitter * (2 * random.random() - 1)))


@dataclass(frozen=True)
class Decision:
    """Retry after `delay`, or fail now with `problem`."""

    retry: bool
    delay: timedelta = timedelta(0)
    problem: dict[str, Any] | None = None


def classify(exc: BaseException, *, stage: str | None = None) -> Failure:
    """The `Failure` an exception raised by an attempt stands for."""
    from sqlalchemy.exc import DBAPIError

    if isinstance(exc, BadInputError):
        kind = FailureKind.BAD_INPUT
    elif isinstance(exc, StorageError | DBAPIError | OSError | MemoryError):
        # OSError covers a full scratch disk and network resets; MemoryError a busy machine.
        kind = FailureKind.TRANSIENT
    else:
        kind = FailureKind.UNEXPECTED
    message = str(exc) or type(exc).__name__
    return Failure(kind, message, error_type=type(exc).__name__, stage=stage)


def decide(failure: Failure, *, attempts: int, max_attempts: int, policy: RetryPolicy) -> Decision:
    """Retry or fail a run whose attempt number `attempts` (1-based) ended in `failure`."""
    if failure.kind == FailureKind.BAD_INPUT:
        return Decision(retry=False, problem=bad_input_problem(failure))
    if attempts < max_attempts:
        return Decision(retry=True, delay=policy.backoff(attempts))
    return Decision(retry=False, problem=exhausted_problem(failure, attempts))


def bad_input_problem(failure: Failure) -> dict[str, Any]:
    return problem_document(
        _slug(failure.error_type),
        "The recording cannot be calibrated",
        422,
        failure.message,
        error=failure.error_type,
        stage=failure.stage,
    )


_EXHAUSTED_TITLES = {
    FailureKind.TRANSIENT: ("storage-or-database-unavailable", "Storage or database unavailable"),
    FailureKind.UNEXPECTED: ("internal-error", "Internal error in the calibration"),
    FailureKind.CRASH: ("worker-crashed", "The calibration process kept dying"),
    FailureKind.TIMEOUT: ("run-timeout", "The calibration kept running too long"),
    FailureKind.LOST: ("worker-lost", "The worker holding the run kept stopping"),
}


def exhausted_problem(failure: Failure, attempts: int) -> dict[str, Any]:
    slug, title = _EXHAUSTED_TITLES.get(failure.kind, ("internal-error", "Internal error"))
    where = f" in stage {failure.stage!r}" if failure.stage else ""
    return problem_document(
        slug,
        title,
        503 if failure.kind == FailureKind.TRANSIENT else 500,
        f"gave up after {attempts} attempt{'s' if attempts != 1 else ''}; "
        f"the last one failed{where}: {failure.message}",
        error=failure.error_type,
        stage=failure.stage,
        attempts=attempts,
    )


def _slug(error_type: str | None) -> str:
    """`NoPointCloudError` -> `no-point-cloud`: each typed input error is its own problem type."""
    if error_type in (None, BadInputError.__name__):
        return "bad-input"
    if error_type == ConfigError.__name__:
        return "invalid-config"
    words = re.findall(r"[A-Z]+(?![a-z])|[A-Z]?[a-z0-9]+", error_type.removesuffix("Error"))
    return "-".join(word.lower() for word in words) or "bad-input"
