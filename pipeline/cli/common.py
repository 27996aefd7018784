"""What every CLI command shares: the recording argument, and typed errors turned into a message
and an exit code."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated

import typer

from pipeline.errors import BadInputError, PipelineError

EXIT_OK = 0
EXIT_FAILED_VERDICT = 1
EXIT_BAD_INPUT = 2

RecordingPath = Annotated[
    Path,
    typer.Argument(help="bag directory, .mcap, .db3, ROS 1 .bag, or .zip/.tar(.gz) of a bag"),
]
"""The recording a command reads, as its first argument."""


@contextmanager
def user_errors() -> Iterator[None]:
    """Run a command body; a `PipelineError` becomes `error: <message>` on stderr and exit code 2.

    No traceback: the message already says what is wrong and what to do.
    """
    try:
        yield
    except BadInputError as err:
        typer.echo(f"error: {err}", err=True)
        raise typer.Exit(EXIT_BAD_INPUT) from None
    except PipelineError as err:
        typer.echo(f"error: {err}", err=True)
        raise typer.Exit(EXIT_BAD_INPUT) from None


def check_writable(path: Path) -> None:
    """Raise `BadInputError` unless a file can be written at `path`, before any work is done:
    a long run must not end in "cannot write". An existing file is opened without truncating
    it; a new one is created and removed again."""
    if path.is_dir():
        raise BadInputError(
            f"cannot write {path}: it is a directory; name a file, e.g. {path / 'result.json'}"
        )
    existed = path.exists()
    try:
        with path.open("r+b" if existed else "xb"):
            pass
    except OSError as err:
        raise BadInputError(
            f"cannot write {path}: {err.strerror or err}; choose a writable path"
        ) from None
    if not existed:
        path.unlink()


def progress(message: str) -> None:
    """One progress line on stderr (stdout stays clean for `--json` output)."""
    print(message, file=sys.stderr, flush=True)
