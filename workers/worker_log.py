"""The worker's log: one logger for all the worker's parts (operators filter on `workers.worker`),
and database errors cut to their first line."""

from __future__ import annotations

import logging

log = logging.getLogger("workers.worker")


def short(err: BaseException) -> str:
    """The first line of `err`, at most 200 characters (SQLAlchemy's messages run to pages)."""
    return str(err).splitlines()[0][:200]
