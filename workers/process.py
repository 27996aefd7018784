"""What every long-running fleetcal process (`worker`, `serve`, `demo`) does alike: its log lines'
format, and stopping on SIGTERM / SIGINT (gently first, at once on a second signal)."""

from __future__ import annotations

import contextlib
import logging
import signal
from collections.abc import Callable, Iterator
from types import FrameType


def configure_logging(level: str) -> None:
    logging.basicConfig(
        level=level.upper(),
        format="%(asctime)s %(levelname)-7s %(name)s: %(message)s",
    )


@contextlib.contextmanager
def stop_signals(request_stop: Callable[..., None]) -> Iterator[None]:
    """While inside: SIGTERM and SIGINT call `request_stop()`, a second one
    `request_stop(now=True)`; the previous handlers come back on leaving."""
    received = [0]

    def handle(signum: int, frame: FrameType | None) -> None:
        received[0] += 1
        now = received[0] > 1
        logging.getLogger(__name__).warning(
            "%s: %s",
            signal.Signals(signum).name,
            "stopping now" if now else "stopping after the running runs",
        )
        request_stop(now=now)

    saved = {signum: signal.signal(signum, handle) for signum in (signal.SIGTERM, signal.SIGINT)}
    try:
        yield
    finally:
        for signum, handler in saved.items():
            signal.signal(signum, handler)
