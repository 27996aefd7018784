"""Opaque keyset cursors: base64url JSON of the last item's sort key, tagged with what it pages.

Keyset (not offset) pagination: a page starts strictly after the previous page's last key, so rows
inserted meanwhile never shift or repeat items. A cursor is decoded only into keys of the shapes
`encode_cursor` writes: whatever else a client sends is an `InvalidCursor`, never a value the
database chokes on (a NUL byte, an id past 64 bits, an instant outside UTC's range).
"""

from __future__ import annotations

import base64
import binascii
import json
import re
import uuid
from collections.abc import Callable
from datetime import datetime
from typing import Any

from service.parameters import in_utc
from service.problem_details import InvalidCursor
from service.schemas import ROBOT_ID_PATTERN

PAGE_SIZE_DEFAULT = 50
PAGE_SIZE_MAX = 500

_BASE64URL = re.compile(r"[A-Za-z0-9_-]*")
_ROW_ID = re.compile(r"0|[1-9][0-9]{0,18}")
_ROW_ID_MAX = 2**63 - 1  # BIGINT on PostgreSQL, INTEGER on SQLite
_DAMAGED = "the cursor is damaged; start again without a cursor"


def encode_cursor(kind: str, *key: Any) -> str:
    values = [value.isoformat() if isinstance(value, datetime) else str(value) for value in key]
    raw = json.dumps([kind, *values], separators=(",", ":")).encode()
    return base64.urlsafe_b64encode(raw).rstrip(b"=").decode()


def decode_cursor(cursor: str, kind: str, *fields: Callable[[str], Any]) -> list[Any]:
    """The key of a cursor made by `encode_cursor(kind, ...)`, each value read by its field's
    parser (`cursor_datetime`, ...); `InvalidCursor` otherwise."""
    try:
        if not _BASE64URL.fullmatch(cursor):  # b64decode would skip the stray bytes
            raise ValueError("not base64url")
        data = json.loads(base64.urlsafe_b64decode(cursor + "=" * (-len(cursor) % 4)))
    except (binascii.Error, ValueError, UnicodeDecodeError) as err:
        raise InvalidCursor(
            "the cursor is not one this API returned; start again without a cursor"
        ) from err
    if (
        not isinstance(data, list)
        or len(data) != len(fields) + 1
        or data[0] != kind
        or not all(isinstance(value, str) for value in data[1:])
    ):
        raise InvalidCursor(
            f"the cursor does not page {kind}; use the next_cursor of the same "
            "listing, or start again without a cursor"
        )
    try:
        return [parse(value) for parse, value in zip(fields, data[1:], strict=True)]
    except ValueError as err:
        raise InvalidCursor(_DAMAGED) from err


def cursor_datetime(value: str) -> datetime:
    """An instant as `encode_cursor` writes it (`isoformat`, with its offset), in UTC."""
    parsed = datetime.fromisoformat(value)
    # The round trip refuses what fromisoformat lets through (on 3.11, a trailing NUL).
    if parsed.tzinfo is None or parsed.isoformat() != value:
        raise ValueError(f"{value!r} is not an instant as this API writes it")
    return in_utc(parsed)


def cursor_row_id(value: str) -> int:
    """A row id: ASCII digits (str.isdigit also takes '²'), within a 64-bit integer."""
    if not _ROW_ID.fullmatch(value) or int(value) > _ROW_ID_MAX:
        raise ValueError(f"{value!r} is not a row id")
    return int(value)


def cursor_uuid(value: str) -> uuid.UUID:
    return uuid.UUID(value)


def cursor_robot_id(value: str) -> str:
    if not re.fullmatch(ROBOT_ID_PATTERN, value):
        raise ValueError(f"{value!r} is not a robot id")
    return value
