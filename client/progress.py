"""Upload progress on stderr: a redrawn bar with rate and ETA on a terminal, plain lines (every
10 %) otherwise, so that a log file of an end-of-line station stays readable."""

from __future__ import annotations

import sys
import time
from typing import TextIO

_REDRAW_S = 0.1
_BAR = 30


class Progress:
    def __init__(self, total: int, stream: TextIO | None = None, tty: bool | None = None) -> None:
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty() if tty is None else tty
        self.total = max(total, 1)
        self.restart()

    def restart(self) -> None:
        """From zero again (a retry sends the body again)."""
        self.sent = 0
        self._started = time.monotonic()
        self._drawn = 0.0
        self._next_step = 10

    def advance(self, n: int) -> None:
        self.sent += n
        now = time.monotonic()
        if self.tty:
            if now - self._drawn >= _REDRAW_S or self.sent >= self.total:
                self._drawn = now
                self.stream.write("\r" + self.describe(now, bar=True))
                if self.sent >= self.total:
                    self.stream.write("\n")
                self.stream.flush()
            return
        percent = 100 * self.sent // self.total
        if percent >= self._next_step:
            self._next_step = (percent // 10 + 1) * 10
            self.line(self.describe(now, bar=False))

    def line(self, message: str) -> None:
        if self.tty and 0 < self.sent < self.total:
            self.stream.write("\n")
        self.stream.write(message + "\n")
        self.stream.flush()

    def describe(self, now: float, *, bar: bool) -> str:
        elapsed = max(now - self._started, 1e-6)
        rate = self.sent / elapsed
        eta = (self.total - self.sent) / rate if rate > 0 else float("inf")
        fraction = min(self.sent / self.total, 1.0)
        text = (
            f"{100 * fraction:3.0f}% {_mb(self.sent)} of {_mb(self.total)} MB, "
            f"{_mb(rate)} MB/s, ETA {_duration(eta)}"
        )
        if not bar:
            return f"uploaded {text}"
        filled = round(_BAR * fraction)
        return f"[{'#' * filled}{' ' * (_BAR - filled)}] {text}"


def _mb(n: float) -> str:
    return f"{n / 1e6:.1f}"


def _duration(seconds: float) -> str:
    if seconds == float("inf"):
        return "?"
    minutes, secs = divmod(round(seconds), 60)
    return f"{minutes}:{secs:02d}"
