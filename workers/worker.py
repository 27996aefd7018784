"""The worker: claims runs from the queue into a pool of pipeline processes, keeps their leases
alive by heartbeat, reaps runs abandoned by dead workers, records each attempt's outcome
through the retry policy, and sends the webhook deliveries of the outbox (`workers.webhooks`).

One thread loops over claims and the children's messages; a second one only renews leases, so a
slow database write in the loop never lets a lease lapse. `request_stop()` drains: no new claims,
running runs get `shutdown_grace` to finish, then they are given back to the queue.
"""

from __future__ import annotations

import logging
import os
import socket
import threading
import time
import uuid
from dataclasses import dataclass, field
from datetime import timedelta
from multiprocessing.connection import wait
from typing import Any

from sqlalchemy.exc import SQLAlchemyError

from service import repository
from service.db import Database
from service.settings import Settings
from workers import queue
from workers.context import JobSpec, load_context
from workers.policy import Failure, FailureKind, RetryPolicy, classify, decide
from workers.pool import Broken, Done, Failed, Pool, PoolError, Slot, Stage, death_message
from workers.queue import Claim
from workers.webhooks import DeliveryOptions, delivery_loop

log = logging.getLogger(__name__)

CALIBRATE_JOB = "workers.job:calibrate_run"
MAX_CLAIM_PAUSE = timedelta(seconds=30)


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
        self._held: dict[uuid.UUID, Claim] = {}
        self._lost: set[uuid.UUID] = set()
        self._lock = threading.Lock()
        self._draining = threading.Event()
        self._stop_now = threading.Event()
        self._stopped = threading.Event()
        self._drain_deadline: float | None = None
        self._outages = 0
        self._claims_paused_until = 0.0

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
        with self._lock:
            return list(self._held.values())

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
        heartbeat = threading.Thread(target=self._heartbeat, name="fleetcal-heartbeat", daemon=True)
        heartbeat.start()
        # Webhooks go out from their own thread: a slow receiver never delays claims or leases.
        webhooks = threading.Thread(
            target=delivery_loop,
            args=(self.db, self.id, DeliveryOptions.from_settings(self.settings), self._stopped),
            name="fleetcal-webhooks",
            daemon=True,
        )
        webhooks.start()
        next_reap = 0.0
        try:
            while not self._stop_now.is_set():
                if self._draining.is_set():
                    if not pool.busy():
                        break
                    if self._drain_deadline is not None and time.monotonic() > self._drain_deadline:
                        log.warning("worker %s: shutdown grace over, giving runs back", self.id)
                        break
                if time.monotonic() >= next_reap:
                    self._reap()
                    next_reap = time.monotonic() + self._reap_interval()
                self._drop_lost(pool)
                self._check_timeouts(pool)
                claimed = False if self._draining.is_set() else self._fill(pool)
                # After a claim, look again at once: a backlog drains without poll delays.
                timeout = 0.0 if claimed else self.options.poll_interval.total_seconds()
                for ready in wait(pool.waitables(), timeout):
                    slot = pool.slot_of(ready)
                    # A replaced child's file descriptors may be reused by its successor: after a
                    # replacement the other ready handles of this round are stale, wait again.
                    if slot is not None and self._on_ready(pool, slot):
                        break
        finally:
            self._stopped.set()
            unfinished = self.held()
            pool.close()  # kills the busy children first: nothing they send can count any more
            for held in unfinished:
                self._give_back(held)
            heartbeat.join(timeout=5)
            webhooks.join(timeout=self.settings.webhook_timeout_seconds + 5)
            if self._own_db:
                self.db.dispose()
            log.info("worker %s stopped", self.id)

    def _reap_interval(self) -> float:
        return min(max(self.lease.total_seconds() / 2, 0.5), 30.0)

    def _reap(self) -> None:
        try:
            reaped = queue.reap(self.db)
        except SQLAlchemyError as err:
            log.warning("reaper: database unavailable (%s); will try again", _short(err))
            return
        for run_id in reaped.requeued:
            log.warning("run %s: its worker stopped heartbeating; back in the queue", run_id)
        for run_id in reaped.failed:
            log.error("run %s: its worker kept dying; failed after its last attempt", run_id)

    def _fill(self, pool: Pool) -> bool:
        """Claim runs for idle slots; True if any was claimed."""
        claimed = False
        if time.monotonic() < self._claims_paused_until:
            return False
        for slot in pool.idle():
            try:
                held = queue.claim(self.db, self.id, self.lease)
            except SQLAlchemyError as err:
                # The database is down or refusing: back off as the policy does for runs,
                # rather than hammering it (and the log) at every poll.
                self._outages += 1
                pause = min(self.options.retry.backoff(self._outages), MAX_CLAIM_PAUSE)
                self._claims_paused_until = time.monotonic() + pause.total_seconds()
                log.warning(
                    "claim: database unavailable (%s); next try in %.1f s",
                    _short(err),
                    pause.total_seconds(),
                )
                break
            self._outages = 0
            if held is None:
                break
            with self._lock:
                self._held[held.run_id] = held
            try:
                with self.db.session() as session:
                    context = load_context(session, held)
            except Exception as err:
                # A database outage, or a profile the worker cannot use: this attempt fails
                # through the policy like any other, instead of taking the worker down.
                self._end_attempt(held, classify(err, stage="claimed"))
                continue
            spec = JobSpec(
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
                self._give_back(held)
                continue
            claimed = True
        return claimed

    # -- children's messages ----------------------------------------------------------------------

    def _on_ready(self, pool: Pool, slot: Slot) -> bool:
        """Handle what `slot`'s child sent or its death; True if the slot was replaced."""
        held: Claim | None = slot.job
        message = pool.receive(slot) if slot.process.is_alive() or slot.connection.poll() else None
        if message is None:
            if held is not None:
                failure = Failure(FailureKind.CRASH, death_message(slot), stage=slot.stage)
                log.error("run %s: %s in stage %s", held.run_id, failure.message, slot.stage)
                self._end_attempt(held, failure)
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
            self._record_stage(held, message)
        elif isinstance(message, Done):
            pool.finish(slot)
            self._store(held, message.result, time.monotonic() - slot.started)
        elif isinstance(message, Failed):
            pool.finish(slot)
            if message.failure.kind != FailureKind.BAD_INPUT:
                # A bad recording is the user's to fix and its message says how (logged once, in
                # `_end_attempt`); any other failure may be ours, and its traceback shows where.
                log.info("run %s: attempt failed: %s", held.run_id, message.traceback.strip())
            self._end_attempt(held, message.failure)
        return False

    def _record_stage(self, held: Claim, stage: Stage) -> None:
        try:
            if not queue.renew(
                self.db, held, self.lease, stage=stage.name, progress=stage.progress
            ):
                self._mark_lost(held)
        except SQLAlchemyError as err:
            log.warning("run %s: cannot record stage %s (%s)", held.run_id, stage.name, _short(err))

    def _store(self, held: Claim, document: dict[str, Any], seconds: float) -> None:
        for attempt in range(1, self.options.store_attempts + 1):
            try:
                queue.complete(self.db, held, document)
            except (repository.LeaseLostError, repository.RunFinishedError) as err:
                log.warning("run %s: result dropped: %s", held.run_id, err)
                break
            except repository.InvalidResultError as err:
                self._end_attempt(
                    held,
                    Failure(
                        FailureKind.UNEXPECTED,
                        str(err),
                        error_type=type(err).__name__,
                        stage="store",
                    ),
                )
                return
            except SQLAlchemyError as err:
                log.warning(
                    "run %s: cannot store the result (%s), try %d of %d",
                    held.run_id,
                    _short(err),
                    attempt,
                    self.options.store_attempts,
                )
                time.sleep(min(2.0**attempt, self.lease.total_seconds() / 4))
                continue
            passed = document.get("verdict", {}).get("passed")
            log.info(
                "run %s: succeeded in %.1f s (%s)",
                held.run_id,
                seconds,
                "passed" if passed else "not passed",
            )
            for warning in document.get("warnings") or ():
                log.warning("run %s: %s", held.run_id, warning)
            break
        else:
            # Nothing more to do here: the lease lapses and the reaper retries the run.
            log.error("run %s: result not stored; the run will be retried", held.run_id)
        self._release(held)

    def _end_attempt(self, held: Claim, failure: Failure) -> None:
        decision = decide(
            failure,
            attempts=held.attempt,
            max_attempts=held.max_attempts,
            policy=self.options.retry,
        )
        try:
            if decision.retry:
                queue.retry(self.db, held, decision.delay)
                log.warning(
                    "run %s: %s; retry in %.1f s",
                    held.run_id,
                    failure.message,
                    decision.delay.total_seconds(),
                )
            else:
                assert decision.problem is not None
                queue.fail(self.db, held, decision.problem)
                if failure.kind == FailureKind.BAD_INPUT:
                    log.info("run %s: failed on bad input: %s", held.run_id, failure.message)
                else:
                    log.error("run %s: failed: %s", held.run_id, decision.problem["detail"])
        except (repository.LeaseLostError, repository.RunFinishedError) as err:
            log.warning("run %s: outcome dropped: %s", held.run_id, err)
        except SQLAlchemyError as err:
            log.error(
                "run %s: cannot record its failure (%s); the reaper will", held.run_id, _short(err)
            )
        self._release(held)

    def _give_back(self, held: Claim) -> None:
        try:
            if queue.give_back(self.db, held):
                log.info("run %s: given back to the queue", held.run_id)
        except SQLAlchemyError as err:
            log.error(
                "run %s: cannot give it back (%s); the reaper will after its lease",
                held.run_id,
                _short(err),
            )
        self._release(held)

    def _release(self, held: Claim) -> None:
        with self._lock:
            self._held.pop(held.run_id, None)
            self._lost.discard(held.run_id)

    # -- leases -----------------------------------------------------------------------------------

    def _heartbeat(self) -> None:
        interval = self.lease.total_seconds() / 3
        while not self._stopped.wait(interval):
            for held in self.held():
                try:
                    alive = queue.renew(self.db, held, self.lease)
                except SQLAlchemyError as err:
                    log.warning("heartbeat: database unavailable (%s)", _short(err))
                    break
                if not alive:
                    self._mark_lost(held)

    def _mark_lost(self, held: Claim) -> None:
        with self._lock:
            if held.run_id in self._held:
                self._lost.add(held.run_id)

    def _drop_lost(self, pool: Pool) -> None:
        """Stop the children whose runs this worker no longer holds: their work would be void."""
        with self._lock:
            lost = set(self._lost)
        for slot in pool.busy():
            held: Claim = slot.job
            if held.run_id in lost:
                log.warning(
                    "run %s: lease lost (reaped or finished elsewhere); stopping it", held.run_id
                )
                self._release(held)
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
                self._end_attempt(
                    held,
                    Failure(
                        FailureKind.TIMEOUT,
                        f"the attempt ran over the worker's limit of {limit}",
                        stage=stage,
                    ),
                )


def _short(err: BaseException) -> str:
    return str(err).splitlines()[0][:200]
