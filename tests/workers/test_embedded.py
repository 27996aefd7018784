"""The embedded service's first start: one admin key, created once, that the API accepts."""

from __future__ import annotations

import socket

import httpx
import pytest

from service.db import Database
from service.settings import Settings
from service.startup import StartupError
from tests.ports import unused_port
from workers.embedded import EmbeddedService, bootstrap_admin_key


def test_the_first_start_creates_one_admin_key_and_later_starts_none(
    settings: Settings, db: Database
) -> None:
    secret = bootstrap_admin_key(db)
    assert secret is not None and secret.startswith("fck_")
    assert bootstrap_admin_key(db) is None

    with EmbeddedService(settings, port=0, workers=0) as service:
        headers = {"X-API-Key": secret}
        response = httpx.put(
            f"{service.url}/v1/robots/R7", json={"model": "m1"}, headers=headers, timeout=30
        )
        assert response.status_code == 201, response.text
        assert httpx.get(f"{service.url}/v1/robots", timeout=30).status_code == 401


def test_prepare_gives_the_port_back_when_the_database_cannot_be_reached() -> None:
    port, db_port = unused_port(), unused_port()
    while db_port == port:
        db_port = unused_port()
    unreachable = Settings(database_url=f"postgresql+psycopg://u@127.0.0.1:{db_port}/db")
    with pytest.raises(StartupError, match="cannot open the database postgresql"):
        EmbeddedService(unreachable, port=port).prepare()
    with socket.socket() as again:
        again.bind(("127.0.0.1", port))
