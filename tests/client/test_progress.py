"""Progress: plain lines every 10 % off a terminal, one redrawn bar with rate and ETA on one."""

from __future__ import annotations

import io

from client.progress import Progress


def test_plain_lines_every_ten_percent_off_a_terminal() -> None:
    stream = io.StringIO()
    progress = Progress(1000, stream=stream, tty=False)
    for _ in range(100):
        progress.advance(10)
    lines = stream.getvalue().splitlines()
    assert len(lines) == 10
    assert lines[-1].startswith("uploaded 100% 0.0 of 0.0 MB")
    assert all("MB/s, ETA" in line and "\r" not in line for line in lines)


def test_a_bar_redrawn_in_place_on_a_terminal() -> None:
    stream = io.StringIO()
    progress = Progress(2_000_000, stream=stream, tty=True)
    progress.advance(1_000_000)
    progress.advance(1_000_000)
    text = stream.getvalue()
    assert text.startswith("\r[###############               ]  50% 1.0 of 2.0 MB")
    assert text.endswith("100% 2.0 of 2.0 MB, " + text.rsplit(", ", 2)[-2] + ", ETA 0:00\n")


def test_a_retry_line_starts_on_its_own_line_and_the_count_restarts() -> None:
    stream = io.StringIO()
    progress = Progress(100, stream=stream, tty=True)
    progress.advance(40)
    progress.line("retrying in 1.0 s")
    progress.restart()
    assert progress.sent == 0
    assert "\nretrying in 1.0 s\n" in stream.getvalue()
