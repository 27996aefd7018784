"""Claiming: queued runs for a pool's idle slots, each started in its slot with what the job
needs (`JobSpec`). While the database is unavailable, claims pause as the retry policy backs off,
rather than hammering it (and the log) at every poll."""

from __future__ import annotations

import time
from datetime import timedelta

from sqlalchemy.exc import SQLAlchemyError

from service.db import Database
from service.settings import Settings
from workers import queue
from workers.context import JobSpec, RunContext, load_context
from workers.holdings import Holdings
from workers.outcomes import Outcomes
from workers.policy import RetryPolicy, classify
from workers.pool import Pool, Slot
from workers.queue import Claim
from workers.worker_log import log, short

MAX_CLAIM_PAUSE = timedelta(seconds=30)


class Claimer:
    def __init__(
        self,
        db: Database,
        settings: Settings,
        holdings: Holdings,
        outcomes: Outcomes,
        *,
        worker_id: str,
        lease: timedelta,
        retry: RetryPolicy,
    ) -> None:
        self.db, self.settings = db, settings
        self.holdings, self.outcomes = holdings, outcomes
        self.worker_id, self.lease, self.retry = worker_id, lease, retry
        self._outages = 0
        self._paused_until = 0.0

    def fill(self, pool: Pool) -> bool:
        """Claim runs for idle slots; True if any was claimed and started."""
        if time.monotonic() < self._paused_until:
            return False
        claimed = False
        for slot in pool.idle():
            try:
                held = queue.claim(self.db, self.worker_id, self.lease)
            except SQLAlchemyError as err:
                self._pause(err)
                break
            self._outages = 0
            if held is None:
                break
            claimed = self._start(pool, slot, held) or claimed
        return claimed

    def _pause(self, err: SQLAlchemyError) -> None:
        self._outages += 1
        pause = min(self.retry.backoff(self._outages), MAX_CLAIM_PAUSE)
        self._paused_until = time.monotonic() + pause.total_seconds()
        log.warning(
            "claim: database unavailable (%s); next try in %.1f s",
            short(err),
            pause.total_seconds(),
        )

    def _start(self, pool: Pool, slot: Slot, held: Claim) -> bool:
        """Start `held` in `slot`; False if its attempt ended first or the run went back."""
        self.holdings.hold(held)
        try:
            with self.db.session() as session:
                context = load_context(session, held)
        except Exception as err:
            # A database outage, or a profile the worker cannot use: this attempt fails
            # through the policy like any other, instead of taking the worker down.
            self.outcomes.end_attempt(held, classify(err, stage="claimed"))
            return False
        spec = self._spec(held, context)
        log.info(
            "run %s: claimed (attempt %d/%d, robot %s, %s)",
            held.run_id,
            held.attempt,
            held.max_attempts,
            held.robot_id,
            held.kind.value,
        )
        try:
            pool.start(slot, held, spec)
        except (BrokenPipeError, OSError):
            # The idle child died unnoticed; its sentinel will report it. The run goes back.
            self.outcomes.give_back(held)
            return False
        return True

    def _spec(self, held: Claim, context: RunContext) -> JobSpec:
        return JobSpec(
            run_id=str(held.run_id),
            attempt=held.attempt,
            robot_id=held.robot_id,
            kind=held.kind.value,
            storage_key=held.storage_key,
            upload_format=held.upload_format,
            config=held.config,
            settings=self.settings,
            context=context,
        )
