"""Opaque keyset cursors: base64url JSON of the last item's sort key, tagged with what it pages.

Keyset (not offset) pagination: a page starts strictly after the previous page's last key, so rows
inserted meanwhile never shift or repeat items.
"""

from __future__ import annotations

import base64
import binascii
import json
from datetime import datetime
from typing import Any

from service.problems import InvalidCursor

PAGE_SIZE_DEFAULT = 50
PAGE_SIZE_MAX = 500


def encode_cursor(kind: str, *key: Any) -> str:
    values = [value.isoformat() if isinstance(value, datetime) else str(value) for value in key]
    raw = json.dumps([kind, *values], separators=(",", ":")).encode()
    return base64.urlsafe_b64encode(raw).rstrip(b"=").decode()


def decode_cursor(cursor: str, kind: str, arity: int) -> list[str]:
    """The key values of a cursor made by `encode_cursor(kind, ...)`; `InvalidCursor` otherwise."""
    try:
        raw = base64.urlsafe_b64decode(cursor + "=" * (-len(cursor) % 4))
        data = json.loads(raw)
    except (binascii.Error, ValueError, UnicodeDecodeError) as err:
        raise InvalidCursor(
            "the cursor is not one this API returned; start again without a cursor"
        ) from err
    if (
        not isinstance(data, list)
        or len(data) != arity + 1
        or data[0] != kind
        or not all(isinstance(value, str) for value in data[1:])
    ):
        raise InvalidCursor(
            f"the cursor does not page {kind}; use the next_cursor of the same "
            "listing, or start again without a cursor"
        )
    return data[1:]


def cursor_datetime(value: str) -> datetime:
    try:
        parsed = datetime.fromisoformat(value)
    except ValueError as err:
        raise InvalidCursor("the cursor is damaged; start again without a cursor") from err
    if parsed.tzinfo is None:
        raise InvalidCursor("the cursor is damaged; start again without a cursor")
    return parsed
