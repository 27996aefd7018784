"""The listings' query parameters, validated in one place: instants that UTC (and so every
database) can hold, text without control characters. Anything else is a 422 problem, not a 500."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Annotated

from fastapi import Query
from pydantic import AfterValidator, AwareDatetime, Field

PLAIN_TEXT_PATTERN = r"^[^\x00-\x1f\x7f]*$"
"""No control characters: PostgreSQL refuses NUL in text, and no frame or name holds one."""


def in_utc(value: datetime) -> datetime:
    """`value` in UTC; ValueError when UTC cannot express it (year 1 or 9999 with an offset).

    Both databases compare instants in UTC, and the conversion overflowed inside the query.
    """
    try:
        return value.astimezone(UTC)
    except OverflowError as err:
        raise ValueError(
            f"{value.isoformat()} is outside the instants UTC can express "
            "(0001-01-01T00:00:00Z to 9999-12-31T23:59:59.999999Z)"
        ) from err


Instant = Annotated[AwareDatetime, AfterValidator(in_utc)]
"""An aware datetime, normalised to UTC."""
PlainText = Annotated[str, Field(pattern=PLAIN_TEXT_PATTERN)]

SinceQuery = Annotated[Instant | None, Query(description="Uploaded at or after.")]
UntilQuery = Annotated[Instant | None, Query(description="Uploaded before.")]
CursorQuery = Annotated[
    str | None, Query(max_length=512, description="The `next_cursor` of the previous page.")
]
FrameQuery = Annotated[PlainText | None, Query(max_length=128, description="One LiDAR frame.")]
