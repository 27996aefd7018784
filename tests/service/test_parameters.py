"""The listings' shared query types: instants UTC can express, text without control characters."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta, timezone

import pytest
from pydantic import TypeAdapter, ValidationError

from service.parameters import Instant, PlainText, in_utc

EDGE_OFFSET = timezone(timedelta(hours=23, minutes=59))


def test_an_instant_is_normalised_to_utc() -> None:
    local = datetime(2026, 1, 1, 1, 30, tzinfo=timezone(timedelta(hours=1)))
    assert in_utc(local) == datetime(2026, 1, 1, 0, 30, tzinfo=UTC)
    assert in_utc(local).tzinfo is UTC
    # The range's own ends, in UTC, stay.
    assert in_utc(datetime.min.replace(tzinfo=UTC)) == datetime.min.replace(tzinfo=UTC)
    assert in_utc(datetime.max.replace(tzinfo=UTC)) == datetime.max.replace(tzinfo=UTC)


@pytest.mark.parametrize(
    "instant",
    [
        datetime.min.replace(tzinfo=EDGE_OFFSET),
        datetime.max.replace(tzinfo=timezone(-timedelta(hours=23, minutes=59))),
    ],
    ids=["before-year-1", "after-year-9999"],
)
def test_an_instant_utc_cannot_express_is_refused(instant: datetime) -> None:
    with pytest.raises(ValueError, match="outside the instants UTC can express"):
        in_utc(instant)
    with pytest.raises(ValidationError, match="outside the instants UTC can express"):
        TypeAdapter(Instant).validate_python(instant.isoformat())


def test_an_instant_needs_its_offset() -> None:
    with pytest.raises(ValidationError, match="timezone"):
        TypeAdapter(Instant).validate_python("2026-01-01T00:00:00")


@pytest.mark.parametrize("text", ["a\x00b", "tab\there", "line\n", "\x1f", "del\x7f"])
def test_plain_text_refuses_control_characters(text: str) -> None:
    with pytest.raises(ValidationError, match="pattern"):
        TypeAdapter(PlainText).validate_python(text)


def test_plain_text_keeps_any_other_character() -> None:
    for text in ("lidar_front", "base link/ü", "雷达", "", "a b"):
        assert TypeAdapter(PlainText).validate_python(text) == text
