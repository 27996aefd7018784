"""The worker: claims runs from the queue into a pool of pipeline processes (`claiming`), keeps
their leases alive by heartbeat (`heartbeat`), reaps runs abandoned by dead workers, records each
attempt's outcome through the retry policy (`outcomes`), and sends the webhook deliveries of the
outbox (`webhooks`).

One thread loops over claims and the children's messages; a second one only renews leases, so a
slow database write in the loop never lets a lease lapse. `request_stop()` drains: no new claims,
running runs get `shutdown_grace` to finish, then they are given back to the queue.
"""

from __future__ import annotations

import os
import socket
import threading
import time
import uuid
from dataclasses import dataclass, field
from datetime import timedelta
from multiprocessing.connection import wait

from sqlalchemy.exc import SQLAlchemyError

from service.db import Database
from service.settings import Settings
from workers import queue
from workers.claiming import Claimer
from workers.heartbeat import renew_leases
from workers.holdings import Holdings
from workers.outcomes import Outcomes
from workers.policy import Failure, FailureKind, RetryPolicy
from workers.pool import Broken, Done, Failed, Pool, PoolError, Slot, Stage, death_message
from workers.queue import Claim
from workers.webhooks import DeliveryOptions, delivery_loop
from workers.worker_log import log, short

CALIBRATE_JOB = "workers.job:calibrate_run"


@dataclass(frozen=True)
class WorkerOptions:
    """How a worker behaves; the lease length and attempts come from `Settings`."""

    concurrency: int = 1
    poll_interval: timedelta = timedelta(seconds=0.25)
    """How often an idle worker looks for queued runs."""
    run_timeout: timedelta | None = timedelta(hours=1)
    """An attempt running longer is stopped and counts as failed (a hung pipeline)."""
    shutdown_grace: timedelta = timedelta(seconds=30)
    """After a stop request, how long running runs may take to finish before they are given back."""
    retry: RetryPolicy = field(default_factory=RetryPolicy)
    job: str = CALIBRATE_JOB
    """The function the pool runs ("module:function"); tests point it elsewhere."""
    store_attempts: int = 3
    """Tries to store a finished result while the database is unavailable, before giving up."""


def worker_id() -> str:
    """`host:pid:random`: unique across machines and restarts, readable in `runs.lease_owner`."""
    return f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:6]}"


class Worker:
    def __init__(
        self, settings: Settings, options: WorkerOptions, *, db: Database | None = None
    ) -> None:
        self.settings = settings
        self.options = options
        self.id = worker_id()
        self.lease = timedelta(seconds=settings.run_lease_seconds)
        self._own_db = db is None
        self.db = db or Database.from_settings(settings)
        self._holdings = Holdings()
        self._outcomes = Outcomes(
            self.db,
            self._holdings,
            lease=self.lease,
            retry=options.retry,
            store_attempts=options.store_attempts,
        )
        self._claimer = Claimer(
            self.db,
            settings,
            self._holdings,
            self._outcomes,
            worker_id=self.id,
            lease=self.lease,
            retry=options.retry,
        )
        self._draining = threading.Event()
        self._stop_now = threading.Event()
        self._stopped = threading.Event()
        self._drain_deadline: float | None = None

    # -- control ----------------------------------------------------------------------------------

    def request_stop(self, *, now: bool = False) -> None:
        """Stop claiming; with `now`, give running runs back at once instead of waiting for them.
        Safe from a signal handler or another thread."""
        if not self._draining.is_set():
            self._drain_deadline = time.monotonic() + self.options.shutdown_grace.total_seconds()
            self._draining.set()
        if now:
            self._stop_now.set()

    def held(self) -> list[Claim]:
        return self._holdings.all()

    # -- main loop --------------------------------------------------------------------------------

    def run(self) -> None:
        """Work until `request_stop()`; always gives back what it still holds when it returns."""
        log.info(
            "worker %s: %d process(es), lease %ss, database %s",
            self.id,
            self.options.concurrency,
            self.settings.run_lease_seconds,
            self.db.engine.dialect.name,
        )
        pool = Pool(self.options.concurrency, self.options.job)
        threads = self._start_threads()
        try:
            self._loop(pool)
        finally:
            self._stopped.set()
            unfinished = self.held()
            pool.close()  # kills the busy children first: nothing they send can count any more
            for held in unfinished:
                self._outcomes.give_back(held)
            heartbeat, webhooks = threads
            heartbeat.join(timeout=5)
            webhooks.join(timeout=self.settings.webhook_timeout_seconds + 5)
            if self._own_db:
                self.db.dispose()
            log.info("worker %s stopped", self.id)

    def _start_threads(self) -> tuple[threading.Thread, threading.Thread]:
        """The heartbeat, and the webhooks' sender (a slow receiver never delays claims or
        leases); both end when the worker has stopped."""
        heartbeat = threading.Thread(
            target=renew_leases,
            args=(self.db, self._holdings, self.lease, self._stopped),
            name="fleetcal-heartbeat",
            daemon=True,
        )
        webhooks = threading.Thread(
            target=delivery_loop,
            args=(self.db, self.id, DeliveryOptions.from_settings(self.settings), self._stopped),
            name="fleetcal-webhooks",
            daemon=True,
        )
        heartbeat.start()
        webhooks.start()
        return heartbeat, webhooks

    def _loop(self, pool: Pool) -> None:
        next_reap = 0.0
        while not self._stop_now.is_set() and not self._drained(pool):
            if time.monotonic() >= next_reap:
                self._reap()
                next_reap = time.monotonic() + self._reap_interval()
            self._drop_lost(pool)
            self._check_timeouts(pool)
            claimed = False if self._draining.is_set() else self._claimer.fill(pool)
            # After a claim, look again at once: a backlog drains without poll delays.
            timeout = 0.0 if claimed else self.options.poll_interval.total_seconds()
            for ready in wait(pool.waitables(), timeout):
                slot = pool.slot_of(ready)
                # A replaced child's file descriptors may be reused by its successor: after a
                # replacement the other ready handles of this round are stale, wait again.
                if slot is not None and self._on_ready(pool, slot):
                    break

    def _drained(self, pool: Pool) -> bool:
        """Whether a drain is over: nothing runs any more, or the shutdown grace is."""
        if not self._draining.is_set():
            return False
        if not pool.busy():
            return True
        if self._drain_deadline is not None and time.monotonic() > self._drain_deadline:
            log.warning("worker %s: shutdown grace over, giving runs back", self.id)
            return True
        return False

    def _reap_interval(self) -> float:
        return min(max(self.lease.total_seconds() / 2, 0.5), 30.0)

    def _reap(self) -> None:
        try:
            reaped = queue.reap(self.db, spare=self._holdings.run_ids())
        except SQLAlchemyError as err:
            log.warning("reaper: database unavailable (%s); will try again", short(err))
            return
        for run_id in reaped.requeued:
            log.warning("run %s: its worker stopped heartbeating; back in the queue", run_id)
        for run_id in reaped.failed:
            log.error("run %s: its worker kept dying; failed after its last attempt", run_id)

    # -- children's messages ----------------------------------------------------------------------

    def _on_ready(self, pool: Pool, slot: Slot) -> bool:
        """Handle what `slot`'s child sent or its death; True if the slot was replaced."""
        held: Claim | None = slot.job
        message = pool.receive(slot) if slot.process.is_alive() or slot.connection.poll() else None
        if message is None:
            if held is not None:
                failure = Failure(FailureKind.CRASH, death_message(slot), stage=slot.stage)
                log.error("run %s: %s in stage %s", held.run_id, failure.message, slot.stage)
                self._outcomes.end_attempt(held, failure)
            else:
                log.warning(
                    "pipeline process %d: %s; starting another", slot.index, death_message(slot)
                )
            pool.replace(slot)
            return True
        if isinstance(message, Broken):
            raise PoolError(f"the pipeline processes cannot start:\n{message.traceback}")
        if held is None:
            return False
        if isinstance(message, Stage):
            self._outcomes.stage(held, message)
        elif isinstance(message, Done):
            pool.finish(slot)
            self._outcomes.store(held, message.result, time.monotonic() - slot.started)
        elif isinstance(message, Failed):
            pool.finish(slot)
            if message.failure.kind != FailureKind.BAD_INPUT:
                # A bad recording is the user's to fix and its message says how (logged once, in
                # `end_attempt`); any other failure may be ours, and its traceback shows where.
                log.info("run %s: attempt failed: %s", held.run_id, message.traceback.strip())
            self._outcomes.end_attempt(held, message.failure)
        return False

    # -- leases -----------------------------------------------------------------------------------

    def _drop_lost(self, pool: Pool) -> None:
        """Stop the children whose runs this worker no longer holds: their work would be void."""
        lost = self._holdings.lost()
        for slot in pool.busy():
            held: Claim = slot.job
            if held.run_id in lost:
                log.warning(
                    "run %s: lease lost (reaped or finished elsewhere); stopping it", held.run_id
                )
                self._holdings.release(held)
                pool.replace(slot)

    def _check_timeouts(self, pool: Pool) -> None:
        limit = self.options.run_timeout
        if limit is None:
            return
        for slot in pool.busy():
            if time.monotonic() - slot.started > limit.total_seconds():
                held: Claim = slot.job
                stage = slot.stage
                pool.replace(slot)
                self._outcomes.end_attempt(
                    held,
                    Failure(
                        FailureKind.TIMEOUT,
                        f"the attempt ran over the worker's limit of {limit}",
                        stage=stage,
                    ),
                )
