"""The heartbeat: renews the leases of the runs a worker holds, in a thread of its own, so that
a slow database write in the main loop never lets a lease lapse."""

from __future__ import annotations

import threading
from datetime import timedelta

from sqlalchemy.exc import SQLAlchemyError

from service.db import Database
from workers import queue
from workers.holdings import Holdings
from workers.worker_log import log, short


def renew_leases(
    db: Database, holdings: Holdings, lease: timedelta, stopped: threading.Event
) -> None:
    """Every third of a lease until `stopped`: renew each held run's lease, and mark the runs
    whose lease is gone as lost (the main loop then stops their children)."""
    interval = lease.total_seconds() / 3
    while not stopped.wait(interval):
        for held in holdings.all():
            try:
                alive = queue.renew(db, held, lease)
            except SQLAlchemyError as err:
                log.warning("heartbeat: database unavailable (%s)", short(err))
                break
            if not alive:
                holdings.mark_lost(held)
