"""A webhook receiver for the tests: a real HTTP server on loopback that checks each delivery's
signature, answers as the test scripts it (500s, a hang), and drops repeats by event id, as a
receiver in the field should."""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

from workers.webhooks import EVENT_ID_HEADER, SIGNATURE_HEADER, verify

Script = Callable[[int, dict[str, Any]], int]
"""(number of the request, 1-based, event) -> the HTTP status to answer."""


@dataclass
class Receiver:
    secret: str
    script: Script = lambda number, event: 200
    port: int = 0
    requests: list[dict[str, Any]] = field(default_factory=list)
    """Every request, in order: event id, signature valid, body, answer."""
    events: dict[str, dict[str, Any]] = field(default_factory=dict)
    """The events answered with 2xx, by id: the receiver's de-duplicated view."""
    duplicates: int = 0
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _server: ThreadingHTTPServer | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/hook"

    def start(self) -> Receiver:
        receiver = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                body = self.rfile.read(int(self.headers["Content-Length"]))
                event = json.loads(body)
                valid = verify(receiver.secret, body, self.headers.get(SIGNATURE_HEADER, ""))
                with receiver._lock:
                    number = len(receiver.requests) + 1
                    entry = {
                        "event_id": self.headers.get(EVENT_ID_HEADER),
                        "signature_valid": valid,
                        "event": event,
                    }
                    receiver.requests.append(entry)
                status = receiver.script(number, event) if valid else 401
                entry["status"] = status
                if 200 <= status < 300:
                    with receiver._lock:
                        if entry["event_id"] in receiver.events:
                            receiver.duplicates += 1
                        receiver.events[entry["event_id"]] = event
                self.send_response(status)
                self.send_header("Content-Length", "0")
                self.end_headers()

            def log_message(self, format: str, *args: Any) -> None:
                pass

        server = ThreadingHTTPServer(("127.0.0.1", self.port), Handler)
        server.daemon_threads = True
        self.port = server.server_address[1]
        self._server = server
        threading.Thread(target=server.serve_forever, name="webhook-receiver", daemon=True).start()
        return self

    def stop(self) -> None:
        """Close the port, as a receiver being redeployed does (connections are refused)."""
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
            self._server = None
