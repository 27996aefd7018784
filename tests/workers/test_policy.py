"""The retry policy: bad input fails at once with its typed message, everything else is retried with
growing backoff until the attempts are used up, then fails with the last reason."""

from __future__ import annotations

from datetime import timedelta

import pytest
from sqlalchemy.exc import OperationalError

from pipeline.errors import BadInputError, ConfigError
from pipeline.io.errors import NoPointCloudError
from service.storage import StorageError
from workers.policy import FailureKind, RetryPolicy, classify, decide

POLICY = RetryPolicy(backoff_base=timedelta(seconds=2), backoff_cap=timedelta(seconds=30), jitter=0)


@pytest.mark.parametrize(
    ("error", "slug"),
    [
        (NoPointCloudError("the recording has no sensor_msgs/PointCloud2 topic"), "no-point-cloud"),
        (ConfigError("reference_frame 'x' is not a LiDAR"), "invalid-config"),
        (BadInputError("degenerate cloud"), "bad-input"),
    ],
)
def test_bad_input_fails_at_the_first_attempt_with_its_message(error: Exception, slug: str) -> None:
    failure = classify(error, stage="read")
    assert failure.kind == FailureKind.BAD_INPUT
    decision = decide(failure, attempts=1, max_attempts=3, policy=POLICY)
    assert not decision.retry and decision.problem is not None
    assert decision.problem["type"] == f"urn:fleetcal:problem:{slug}"
    assert decision.problem["detail"] == str(error)
    assert decision.problem["status"] == 422
    assert decision.problem["error"] == type(error).__name__
    assert decision.problem["stage"] == "read"


@pytest.mark.parametrize(
    ("error", "kind"),
    [
        (StorageError("cannot read recordings/R1/x: connection reset"), FailureKind.TRANSIENT),
        (
            OperationalError("SELECT 1", {}, Exception("server closed the connection")),
            FailureKind.TRANSIENT,
        ),
        (OSError(28, "No space left on device"), FailureKind.TRANSIENT),
        (ZeroDivisionError("division by zero"), FailureKind.UNEXPECTED),
    ],
)
def test_other_errors_are_retried_with_growing_backoff(error: Exception, kind: FailureKind) -> None:
    failure = classify(error)
    assert failure.kind == kind
    delays = [decide(failure, attempts=n, max_attempts=5, policy=POLICY) for n in (1, 2, 3, 4)]
    assert all(d.retry for d in delays)
    assert [d.delay.total_seconds() for d in delays] == [2, 4, 8, 16]


def test_the_last_attempt_fails_with_the_reason() -> None:
    failure = classify(StorageError("bucket unreachable"), stage="download")
    decision = decide(failure, attempts=3, max_attempts=3, policy=POLICY)
    assert not decision.retry and decision.problem is not None
    assert decision.problem["type"] == "urn:fleetcal:problem:storage-or-database-unavailable"
    assert decision.problem["detail"] == (
        "gave up after 3 attempts; the last one failed in stage 'download': bucket unreachable"
    )
    assert decision.problem["attempts"] == 3


def test_backoff_is_capped_and_jittered() -> None:
    policy = RetryPolicy(backoff_base=timedelta(seconds=10), backoff_cap=timedelta(seconds=60))
    delays = {policy.backoff(attempts).total_seconds() for attempts in [8] * 50}
    assert all(48 <= d <= 72 for d in delays)
    assert len(delays) > 1, "jitter spreads runs that failed together"
