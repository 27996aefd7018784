"""The narrow adapter around rosbags' and mcap's calls: where their errors come from is known by
where they were caught, not guessed afterwards.

Damaged bytes make the libraries raise plain Python errors: a consistency `assert`, a length field
asking for an absurd read (`MemoryError`, `OverflowError`), a lookup of an id that does not exist
(`KeyError`, `IndexError`), a bad value (`ValueError`). From our own code the same types are bugs
and must stay visible, so each call into a library is made through `library_call()` (one call) or
`guarded()` (a library's message iterator), which wrap those errors in `LibraryError`;
`source.reading_errors` reports a `LibraryError` as a damaged recording, with a remedy.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import TypeVar

T = TypeVar("T")

LIBRARY_ERRORS: tuple[type[Exception], ...] = (
    AssertionError,
    MemoryError,
    OverflowError,
    ValueError,
    IndexError,
    KeyError,
)
"""What rosbags and mcap raise on damaged bytes besides their own error types (which
`source.READ_ERRORS` lists and which mean damage wherever they are raised)."""


class LibraryError(Exception):
    """`cause` was raised inside a call into rosbags or mcap while they read a recording."""

    def __init__(self, cause: Exception) -> None:
        super().__init__(str(cause))
        self.cause = cause


@contextmanager
def library_call() -> Iterator[None]:
    """Around one call into rosbags or mcap, and nothing of ours."""
    try:
        yield
    except LIBRARY_ERRORS as err:
        raise LibraryError(err) from err


def guarded(items: Iterator[T]) -> Iterator[T]:
    """`items`, a library's iterator, each step taken as a `library_call` (what the consumer does
    with an item is not)."""
    while True:
        try:
            item = next(items)
        except StopIteration:
            return
        except LIBRARY_ERRORS as err:
            raise LibraryError(err) from err
        yield item
