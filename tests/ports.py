"""Loopback ports for the start-up tests."""

from __future__ import annotations

import socket


def unused_port() -> int:
    """A loopback port nothing listens on now (bound by the system, then released)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])
