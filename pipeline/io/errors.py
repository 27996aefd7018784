"""Errors of `pipeline.io`: each says what is wrong with the recording and what the user can do."""

from __future__ import annotations

from pipeline.errors import BadInputError


class RecordingError(BadInputError):
    """Base of every error about a recording's content or format."""


class UnknownFormatError(RecordingError):
    """The file is not a recording we can read (checked by its magic bytes, not its name)."""


class CorruptRecordingError(RecordingError):
    """The file looks like a recording but cannot be decoded (truncated, damaged, unsafe archive)."""
