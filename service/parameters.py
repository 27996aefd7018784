"""The listings' query parameters, validated in one place: instants written as RFC 3339 that UTC
(and so every database) can hold, text without control characters, each parameter given once.
Anything else is a 422 problem, not a 500."""

from __future__ import annotations

import re
from datetime import UTC, datetime
from typing import Annotated

from fastapi import Query, Request
from fastapi.exceptions import RequestValidationError
from pydantic import AfterValidator, AwareDatetime, BeforeValidator, Field

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


_RFC_3339_DATE = re.compile(r"\d{4}-\d{2}-\d{2}[Tt ]")


def written_as_rfc_3339(value: object) -> object:
    """`value` unless it is text that is no RFC 3339 date-time.

    pydantic reads a number as seconds since 1970 ("12" or "3.6e-36" is 1970-01-01), which the
    API's document does not offer and no client means by an instant."""
    if isinstance(value, str) and not _RFC_3339_DATE.match(value):
        raise ValueError(f"{value!r} is no RFC 3339 date-time; write e.g. 2026-01-31T12:00:00Z")
    return value


Instant = Annotated[AwareDatetime, BeforeValidator(written_as_rfc_3339), AfterValidator(in_utc)]
"""An aware datetime, normalised to UTC."""
PlainText = Annotated[str, Field(pattern=PLAIN_TEXT_PATTERN)]

SinceQuery = Annotated[Instant | None, Query(description="Uploaded at or after.")]
UntilQuery = Annotated[Instant | None, Query(description="Uploaded before.")]
CursorQuery = Annotated[
    str | None, Query(max_length=512, description="The `next_cursor` of the previous page.")
]
FrameQuery = Annotated[PlainText | None, Query(max_length=128, description="One LiDAR frame.")]


def refuse_repeated_query_parameters(request: Request) -> None:
    """A 422 for a query parameter given more than once (`?frame=a&frame=b`).

    No parameter of the API takes a list; FastAPI would keep the last value and drop the rest,
    so the answer would silently not be the one asked for."""
    seen: set[str] = set()
    repeated = []
    for name, _ in request.query_params.multi_items():
        if name in seen and name not in repeated:
            repeated.append(name)
        seen.add(name)
    if repeated:
        raise RequestValidationError(
            [
                {
                    "loc": ("query", name),
                    "msg": "given more than once; give each query parameter at most once",
                    "type": "repeated_parameter",
                }
                for name in repeated
            ]
        )
