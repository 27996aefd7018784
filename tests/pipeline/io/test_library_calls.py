"""The adapter around rosbags' and mcap's calls: plain errors raised inside a library call become
`LibraryError`, the same errors anywhere else (our code, the consumer of an iterator) stay as
they are."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from pipeline.io.errors import CorruptRecordingError
from pipeline.io.library_calls import LIBRARY_ERRORS, LibraryError, guarded, library_call


@pytest.mark.parametrize("kind", LIBRARY_ERRORS)
def test_a_plain_error_in_a_library_call_is_wrapped_with_its_cause(
    kind: type[Exception],
) -> None:
    raised = kind("chunk 7")
    with pytest.raises(LibraryError) as caught, library_call():
        raise raised
    assert caught.value.cause is raised and caught.value.__cause__ is raised


@pytest.mark.parametrize("raised", [TypeError("bug"), CorruptRecordingError("damaged")])
def test_other_errors_pass_a_library_call_unchanged(raised: Exception) -> None:
    with pytest.raises(type(raised)) as caught, library_call():
        raise raised
    assert caught.value is raised


def _messages(fail_after: int) -> Iterator[int]:
    yield from range(fail_after)
    raise KeyError("connection 9")


def test_guarded_wraps_what_the_iterator_raises() -> None:
    seen = []
    with pytest.raises(LibraryError, match="connection 9"):
        for item in guarded(_messages(3)):
            seen.append(item)
    assert seen == [0, 1, 2]


def test_guarded_leaves_what_the_consumer_raises() -> None:
    with pytest.raises(KeyError, match="ours"):
        for _ in guarded(_messages(3)):
            raise KeyError("ours")
