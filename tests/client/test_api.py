"""Retries: 503 (with Retry-After) and network errors are retried with backoff; other problems are
answered at once. Against a stdlib HTTP server that answers 503 a set number of times."""

from __future__ import annotations

import json
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from client.api import Api
from client.errors import RefusedError


class Flaky(BaseHTTPRequestHandler):
    unavailable = 2
    seen = 0
    final_status = 200

    def do_GET(self) -> None:
        type(self).seen += 1
        busy = type(self).seen <= type(self).unavailable
        status = 503 if busy else type(self).final_status
        body = json.dumps(
            {"type": "https://fleetcal.dev/problems/unavailable", "detail": "database restarting"}
            if status != 200
            else {"items": []}
        ).encode()
        self.send_response(status)
        if busy:
            self.send_header("Retry-After", "0")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args: object) -> None:
        pass


@pytest.fixture
def flaky() -> Iterator[str]:
    Flaky.seen, Flaky.unavailable, Flaky.final_status = 0, 2, 200
    server = ThreadingHTTPServer(("127.0.0.1", 0), Flaky)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()


def test_503_is_retried_until_the_service_answers(flaky: str) -> None:
    said: list[str] = []
    api = Api(flaky, "key", retries=3, backoff_s=0.01, on_retry=said.append)
    assert api.json("GET", "/v1/runs") == {"items": []}
    assert Flaky.seen == 3
    assert len(said) == 2 and all("HTTP 503 unavailable: database restarting" in s for s in said)


def test_a_problem_other_than_502_to_504_is_not_retried(flaky: str) -> None:
    Flaky.unavailable, Flaky.final_status = 0, 409
    with pytest.raises(RefusedError, match="HTTP 409 unavailable: database restarting"):
        Api(flaky, "key", retries=3, backoff_s=0.01).json("GET", "/v1/runs")
    assert Flaky.seen == 1
