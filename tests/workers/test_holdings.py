"""What a worker holds: a lost lease counts only for a run still held, and releasing a run
forgets both."""

from __future__ import annotations

import uuid
from datetime import UTC, datetime

from service.models import RunKind
from workers.holdings import Holdings
from workers.queue import Claim


def claim() -> Claim:
    now = datetime.now(UTC)
    return Claim(
        run_id=uuid.uuid4(),
        robot_id="R1",
        kind=RunKind.MAINTENANCE,
        storage_key="k",
        upload_format="mcap",
        config=None,
        attempt=1,
        max_attempts=3,
        lease_owner="w:1",
        created_at=now,
        available_at=now,
        claimed_at=now,
    )


def test_a_lost_lease_counts_only_while_the_run_is_held() -> None:
    holdings, held, other = Holdings(), claim(), claim()
    holdings.hold(held)
    holdings.mark_lost(held)
    holdings.mark_lost(other)  # released already, or never held: nothing to stop
    assert holdings.all() == [held]
    assert holdings.lost() == {held.run_id}


def test_release_forgets_the_run_and_its_lost_lease() -> None:
    holdings, held = Holdings(), claim()
    holdings.hold(held)
    holdings.mark_lost(held)
    holdings.release(held)
    assert holdings.all() == [] and holdings.lost() == set()
    holdings.release(held)  # twice is harmless: a failure and a stop may both release
