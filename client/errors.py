"""The client's one exception family; each error carries the exit code the CLI ends with."""

from __future__ import annotations

EXIT_PASSED = 0
EXIT_FAILED_VERDICT = 1
EXIT_REFUSED = 2
EXIT_UNREACHABLE = 3


class ClientError(Exception):
    """Base of the client's errors; `exit_code` is what `fleetcal` exits with."""

    exit_code = EXIT_REFUSED


class BadInputError(ClientError):
    """The recording, config file or options cannot be sent as they are."""


class RefusedError(ClientError):
    """The service answered with a problem that a retry cannot change (4xx, 5xx but 502-504)."""


class UnreachableError(ClientError):
    """No answer from the service (network errors, 502-504) after every retry."""

    exit_code = EXIT_UNREACHABLE
