"""Cursors decode only into keys of the shapes `encode_cursor` writes: whatever else is an
`InvalidCursor`, before any value reaches the database."""

from __future__ import annotations

import uuid
from collections.abc import Callable
from datetime import UTC, datetime
from typing import Any

import pytest

from service.pagination import (
    cursor_datetime,
    cursor_robot_id,
    cursor_row_id,
    cursor_uuid,
    decode_cursor,
    encode_cursor,
)
from service.problem_details import InvalidCursor

MEASURED = datetime(2026, 1, 2, 3, 4, 5, 678_000, tzinfo=UTC)
RUN_ID = uuid.UUID("12345678-1234-4234-8234-123456789abc")


def assert_damaged(kind: str, key: list[Any], *fields: Callable[[str], Any]) -> None:
    """A well-formed cursor of `kind` holding `key` is refused for what its key holds."""
    with pytest.raises(InvalidCursor, match="damaged"):
        decode_cursor(encode_cursor(kind, *key), kind, *fields)


def test_every_listing_s_key_round_trips() -> None:
    history = encode_cursor("history", MEASURED, 2**63 - 1)
    assert decode_cursor(history, "history", cursor_datetime, cursor_row_id) == [
        MEASURED,
        2**63 - 1,
    ]
    runs = encode_cursor("runs", MEASURED, RUN_ID)
    assert decode_cursor(runs, "runs", cursor_datetime, cursor_uuid) == [MEASURED, RUN_ID]
    robots = encode_cursor("robots", "R1.a_b-c")
    assert decode_cursor(robots, "robots", cursor_robot_id) == ["R1.a_b-c"]


@pytest.mark.parametrize(
    "row_id",
    [
        "1" * 31,  # SQLite: OverflowError binding it
        str(2**63),  # one past BIGINT
        "²",  # str.isdigit() says yes, int() says no
        "١٢",  # Arabic-Indic digits: int() reads 12, but no cursor holds them
        "-1",
        "01",
        "1\x00",
        "",
        " 1",
    ],
)
def test_a_history_row_id_that_is_no_64_bit_integer_is_refused(row_id: str) -> None:
    assert_damaged("history", [MEASURED, row_id], cursor_datetime, cursor_row_id)


@pytest.mark.parametrize(
    "instant",
    [
        "2026-01-02T03:04:05+00:00\x00",  # Python 3.11's fromisoformat ignores the NUL
        "0001-01-01T00:00:00+23:59",  # before year 1 in UTC
        "9999-12-31T23:59:59-23:59",  # after year 9999 in UTC
        "2026-01-02T03:04:05",  # no offset
        "2026-01-02 03:04:05+00:00",  # not as isoformat() writes it
        "20260102T030405Z",
        "yesterday",
    ],
)
def test_an_instant_not_written_by_the_api_is_refused(instant: str) -> None:
    assert_damaged("runs", [instant, RUN_ID], cursor_datetime, cursor_uuid)


@pytest.mark.parametrize("robot_id", ["R\x001", "R1\n", "-R1", "a/b", "x" * 65, ""])
def test_a_robots_cursor_holding_no_robot_id_is_refused(robot_id: str) -> None:
    assert_damaged("robots", [robot_id], cursor_robot_id)


@pytest.mark.parametrize(
    "cursor",
    [
        encode_cursor("robots", "R1") + "\x00",  # b64decode would skip the NUL
        "WyJyb2JvdHMiLCJSMSJd!",
        "not base64 at all",
        "bm90IGpzb24",  # "not json"
    ],
)
def test_a_cursor_that_is_not_base64url_json_is_refused(cursor: str) -> None:
    with pytest.raises(InvalidCursor, match="not one this API returned"):
        decode_cursor(cursor, "robots", cursor_robot_id)


def test_a_cursor_of_another_listing_or_arity_is_refused() -> None:
    with pytest.raises(InvalidCursor, match="does not page robots"):
        decode_cursor(encode_cursor("runs", MEASURED, RUN_ID), "robots", cursor_robot_id)
    with pytest.raises(InvalidCursor, match="does not page history"):
        decode_cursor(encode_cursor("history", MEASURED), "history", cursor_datetime, cursor_row_id)
