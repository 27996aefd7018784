"""How an attempt ends in the database: its stages as it runs, then its result stored, or its
failure through the retry policy (a retry later, or the run failed), or the run given back to the
queue. Whatever happens, the worker stops holding the run."""

from __future__ import annotations

import time
from datetime import timedelta
from typing import Any

from sqlalchemy.exc import SQLAlchemyError

from service import repository
from service.db import Database
from workers import queue
from workers.holdings import Holdings
from workers.policy import Failure, FailureKind, RetryPolicy, decide
from workers.pool import Stage
from workers.queue import Claim
from workers.worker_log import log, short


class Outcomes:
    def __init__(
        self,
        db: Database,
        holdings: Holdings,
        *,
        lease: timedelta,
        retry: RetryPolicy,
        store_attempts: int,
    ) -> None:
        self.db = db
        self.holdings = holdings
        self.lease = lease
        self.retry = retry
        self.store_attempts = store_attempts

    def stage(self, held: Claim, stage: Stage) -> None:
        """The stage the run reached (which renews its lease too)."""
        try:
            if not queue.renew(
                self.db, held, self.lease, stage=stage.name, progress=stage.progress
            ):
                self.holdings.mark_lost(held)
        except SQLAlchemyError as err:
            log.warning("run %s: cannot record stage %s (%s)", held.run_id, stage.name, short(err))

    def store(self, held: Claim, document: dict[str, Any], seconds: float) -> None:
        """Store the result, retrying `store_attempts` times while the database is unavailable."""
        for attempt in range(1, self.store_attempts + 1):
            try:
                queue.complete(self.db, held, document)
            except (repository.LeaseLostError, repository.RunFinishedError) as err:
                log.warning("run %s: result dropped: %s", held.run_id, err)
                break
            except repository.InvalidResultError as err:
                failure = Failure(
                    FailureKind.UNEXPECTED, str(err), error_type=type(err).__name__, stage="store"
                )
                self.end_attempt(held, failure)
                return
            except SQLAlchemyError as err:
                log.warning(
                    "run %s: cannot store the result (%s), try %d of %d",
                    held.run_id,
                    short(err),
                    attempt,
                    self.store_attempts,
                )
                time.sleep(min(2.0**attempt, self.lease.total_seconds() / 4))
                continue
            _log_stored(held, document, seconds)
            break
        else:
            # Nothing more to do here: the lease lapses and the reaper retries the run.
            log.error("run %s: result not stored; the run will be retried", held.run_id)
        self.holdings.release(held)

    def end_attempt(self, held: Claim, failure: Failure) -> None:
        """The attempt failed: retry the run after the policy's delay, or fail it."""
        decision = decide(
            failure, attempts=held.attempt, max_attempts=held.max_attempts, policy=self.retry
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
                "run %s: cannot record its failure (%s); the reaper will", held.run_id, short(err)
            )
        self.holdings.release(held)

    def give_back(self, held: Claim) -> None:
        """Back to the queue without counting the attempt (a stop, a child that died idle)."""
        try:
            if queue.give_back(self.db, held):
                log.info("run %s: given back to the queue", held.run_id)
        except SQLAlchemyError as err:
            log.error(
                "run %s: cannot give it back (%s); the reaper will after its lease",
                held.run_id,
                short(err),
            )
        self.holdings.release(held)


def _log_stored(held: Claim, document: dict[str, Any], seconds: float) -> None:
    passed = document.get("verdict", {}).get("passed")
    log.info(
        "run %s: succeeded in %.1f s (%s)",
        held.run_id,
        seconds,
        "passed" if passed else "not passed",
    )
    for warning in document.get("warnings") or ():
        log.warning("run %s: %s", held.run_id, warning)
