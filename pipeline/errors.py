"""The exception family of the numerical core: every error `pipeline` raises derives from these."""

from __future__ import annotations


class PipelineError(Exception):
    """Base of every error raised by `pipeline`. The message says what is wrong and what to do."""


class BadInputError(PipelineError):
    """The input cannot be used as given (a corrupt recording, a bad config, a degenerate cloud).

    Retrying the same input gives the same error; the worker fails such a run at once.
    """


class ConfigError(BadInputError):
    """A pipeline configuration value or file is invalid."""
