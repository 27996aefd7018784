"""Bad requests the service tests leave out, on SQLite and PostgreSQL: over a real HTTP server
(uvicorn, as `fleetcal serve` runs it) a huge request head, a Content-Length that lies either way
or exceeds the limit; through the app, JSON that does not parse, cursors of every listing that
were damaged or belong to another listing, unknown robots and runs. Each gets its status and
problem type; nothing is stored."""

from __future__ import annotations

import hashlib
import json
import socket
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from service.db import Database
from service.settings import Settings
from service.storage import LocalStorage
from tests.reliability.harness import wait_for
from tests.service.conftest import Api, make_keys, problem_type, recording
from workers.embedded import EmbeddedService

UPLOAD = "/v1/robots/R1/runs?kind=end_of_line"


class Server:
    """The API over HTTP on loopback, its key, and what it stored."""

    def __init__(self, service: EmbeddedService, key: str, db: Database) -> None:
        self.service, self.key, self.db = service, key, db
        self.storage = LocalStorage(Path(service.settings.resolved_storage_url[len("file://") :]))

    def connect(self) -> socket.socket:
        return socket.create_connection(("127.0.0.1", self.service.port), timeout=60)

    def head(self, content_length: int, **headers: str) -> bytes:
        lines = [f"POST {UPLOAD} HTTP/1.1", "Host: fleetcal", f"X-API-Key: {self.key}"]
        lines += [f"Content-Length: {content_length}"] + [f"{k}: {v}" for k, v in headers.items()]
        return ("\r\n".join(lines) + "\r\n\r\n").encode()

    def nothing_stored(self) -> bool:
        from sqlalchemy import func, select

        from service.models import Run

        with self.db.session() as session:
            runs = session.scalar(select(func.count()).select_from(Run))
        return runs == 0 and not [p for p in self.storage.root.rglob("*") if p.is_file()]


def answer(sock: socket.socket) -> tuple[int, dict[str, str], bytes]:
    """Status, headers and body of one HTTP/1.1 response with a Content-Length."""
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = sock.recv(65536)
        assert chunk, f"the server closed without answering: {data!r}"
        data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    status_line, *lines = head.decode().split("\r\n")
    headers = {k.lower(): v.strip() for k, _, v in (line.partition(":") for line in lines)}
    while len(body) < int(headers.get("content-length", 0)):
        body += sock.recv(65536)
    return int(status_line.split()[1]), headers, body


def problem_of(headers: dict[str, str], body: bytes) -> str:
    assert headers["content-type"].startswith("application/problem+json"), body
    return str(json.loads(body)["type"]).removeprefix("urn:fleetcal:problem:")


@pytest.fixture
def server(settings: Settings) -> Iterator[Server]:
    db = Database.from_settings(settings)
    key = make_keys(db)["upload_r1"]
    with EmbeddedService(settings, port=0, workers=0) as service:
        yield Server(service, key, db)
    db.dispose()


def test_a_huge_request_head_is_refused_with_431_and_the_server_keeps_serving(
    server: Server,
) -> None:
    with server.connect() as sock:
        sock.sendall(server.head(4096)[:-2])  # the head, not yet ended...
        filler = b"X-Filler: " + b"a" * (64 * 1024) + b"\r\n"
        try:
            for _ in range(64):  # ...then 4 MiB more of it
                sock.sendall(filler)
        except (BrokenPipeError, ConnectionResetError):
            pass  # refused while sending, as it should be
        status, headers, body = answer(sock)
    assert status == 431 and problem_of(headers, body) == "request-head-too-large"
    assert server.nothing_stored()
    # A large but sane head (the calibration config header is allowed 16 KiB) still passes.
    config = json.dumps({"reader": {"lidar_topics": ["/l" * 4000]}})
    response = httpx.post(
        f"{server.service.url}{UPLOAD}",
        content=recording(),
        headers={"X-API-Key": server.key, "X-Fleetcal-Config": config, "X-Pad": "p" * 32_000},
        timeout=60,
    )
    assert response.status_code == 202, response.text


def test_a_body_shorter_than_its_content_length_then_a_hang_up_stores_nothing(
    server: Server,
) -> None:
    body = recording(100_000)
    with server.connect() as sock:
        sock.sendall(server.head(len(body) * 2) + body)
        sock.shutdown(socket.SHUT_WR)
    # Wait for the app to have seen the hang-up: before it reads the request there is no
    # temporary file either, and "none left" would pass too early.
    wait_for("the app to count the cut-off upload", lambda: _refused(server, "client-disconnected"))
    wait_for("the server to drop the upload", lambda: server.storage.temporary_uploads() == [])
    assert server.nothing_stored()


def test_a_body_longer_than_its_content_length_is_caught_by_its_checksum(
    server: Server,
) -> None:
    """The request ends where Content-Length says; the bytes after it are no request: uvicorn
    answers a plain 400 and closes the connection, and the app sees its upload cut off (or, if it
    got there first, refuses the body's first half by its checksum). Nothing is kept either way."""
    body = recording(100_000)
    with server.connect() as sock:
        digest = hashlib.sha256(body).hexdigest()
        sock.sendall(server.head(len(body) // 2, **{"X-Content-SHA256": digest}) + body)
        status, headers, reply = answer(sock)
    assert status in (400, 422), reply
    if status == 422:
        assert problem_of(headers, reply) == "checksum-mismatch"

    wait_for(
        "the app to refuse the upload",
        lambda: _refused(server, "checksum-mismatch", "client-disconnected"),
    )
    assert server.nothing_stored()


def _refused(server: Server, *outcomes: str) -> bool:
    """Whether the app has counted one upload ending with one of `outcomes`."""
    metrics = httpx.get(f"{server.service.url}/metrics", timeout=30).text
    return any(
        f'fleetcal_uploads_total{{outcome="{outcome}"}} 1.0' in metrics for outcome in outcomes
    )


def test_a_content_length_over_the_limit_is_refused_before_the_body(server: Server) -> None:
    """The answer comes without one byte of the body sent: nothing waits for 3 GiB."""
    with server.connect() as sock:
        sock.sendall(server.head(3 * 1024**3))
        status, headers, body = answer(sock)
    assert status == 413 and problem_of(headers, body) == "upload-too-large"
    assert server.nothing_stored()


# -- through the app ----------------------------------------------------------------------------


def test_json_that_does_not_parse_is_a_422_problem(api: Api) -> None:
    for path in ("/v1/robots/R9", "/v1/tolerance-profiles/p1"):
        for text in ('{"model": "mk2"', "{'model': 'mk2'}", "\xff\xfe", "", "null", "[]"):
            response = api.client.put(
                path,
                content=text.encode("utf-8", "surrogateescape"),
                headers=api.headers("admin", **{"Content-Type": "application/json"}),
            )
            assert response.status_code == 422, (path, text, response.text)
            assert problem_type(response) == "invalid-request"
    assert api.client.get("/v1/robots/R9", headers=api.headers("read")).status_code == 404


def test_damaged_and_foreign_cursors_are_400_problems(api: Api) -> None:
    from service.pagination import encode_cursor

    api.upload("R1")
    runs_cursor = encode_cursor("runs", "2024-01-01T00:00:00+00:00", "0" * 32)
    damaged = [
        "garbage!",
        "e30",  # {}
        encode_cursor("robots", "R1", "extra"),
        encode_cursor("history", "not a date", "1"),
        encode_cursor("history", "2024-01-01T00:00:00+00:00", "not-a-number"),
        encode_cursor("history", "2024-01-01T00:00:00", "1"),  # no time zone
    ]
    for path in ("/v1/robots", "/v1/fleet", "/v1/robots/R1/history"):
        for cursor in [*damaged, runs_cursor]:
            response = api.client.get(path, params={"cursor": cursor}, headers=api.headers("read"))
            assert response.status_code == 400, (path, cursor, response.text)
            assert problem_type(response) == "invalid-cursor"


def test_unknown_robots_and_runs_are_404_problems(api: Api) -> None:
    read = api.headers("read")
    for path in ("/v1/robots/nobody", "/v1/robots/nobody/calibration", "/v1/robots/nobody/history"):
        response = api.client.get(path, headers=read)
        assert response.status_code == 404 and problem_type(response) == "robot-not-found", path
    unknown = "/v1/runs/00000000-0000-4000-8000-000000000000"
    for suffix in ("", "/report", "/report/map-top.png", "/exports/urdf"):
        response = api.client.get(unknown + suffix, headers=read)
        assert response.status_code == 404 and problem_type(response) == "run-not-found", suffix
    for bad in ("/v1/runs/not-a-uuid", "/v1/runs/1", "/v1/runs/00000000-0000-4000-8000"):
        response = api.client.get(bad, headers=read)
        assert response.status_code == 422 and problem_type(response) == "invalid-request"


# -- what an outside probe found (issue 15): each was a 500 ---------------------------------------

LISTINGS_WITH_INSTANTS = ("/v1/runs", "/v1/robots/R1/history")


def test_instants_utc_cannot_express_are_422_problems(api: Api) -> None:
    """An offset at the end of the range: the conversion to UTC overflowed inside the query."""
    api.upload("R1")
    read = api.headers("read")
    for path in LISTINGS_WITH_INSTANTS:
        for name in ("since", "until"):
            for instant in ("0001-01-01T00:00:00+23:59", "9999-12-31T23:59:59-23:59"):
                response = api.client.get(path, params={name: instant}, headers=read)
                assert response.status_code == 422, (path, name, instant, response.text)
                assert problem_type(response) == "invalid-request"
                assert "outside the instants UTC can express" in response.json()["detail"]
        # The range's own ends, in UTC, are instants like any other.
        widest = {"since": "0001-01-01T00:00:00Z", "until": "9999-12-31T23:59:59.999999Z"}
        assert api.client.get(path, params=widest, headers=read).status_code == 200, path


def test_instants_written_as_numbers_are_422_problems(api: Api) -> None:
    """pydantic read "12" or "3.6e-36" as seconds since 1970 and the listing answered 200 for an
    instant nobody asked for (schemathesis' linked sequences found it)."""
    api.upload("R1")
    read = api.headers("read")
    for path in (*LISTINGS_WITH_INSTANTS, "/v1/robots/R1/history.csv"):
        for instant in ("12", "3.656681247237943e-36", "-1", "1e10", "2026"):
            response = api.client.get(path, params={"until": instant}, headers=read)
            assert response.status_code == 422, (path, instant, response.text)
            assert problem_type(response) == "invalid-request"
            assert "RFC 3339" in response.json()["detail"], response.text
        for instant in ("2026-01-31T12:00:00Z", "2026-01-31 12:00:00+01:00"):
            response = api.client.get(path, params={"until": instant}, headers=read)
            assert response.status_code == 200, (path, instant, response.text)


def test_a_query_parameter_given_twice_is_a_422_problem(api: Api) -> None:
    """No parameter takes a list: FastAPI kept the last of `frame=a&frame=K` and answered for K."""
    api.upload("R1")
    read = api.headers("read")
    for query in (
        "frame=&frame=a&frame=K",
        "limit=1&limit=2",
        "since=2026-01-01T00:00:00Z&since=x",
    ):
        response = api.client.get(f"/v1/robots/R1/history?{query}", headers=read)
        assert response.status_code == 422, (query, response.text)
        assert problem_type(response) == "invalid-request"
        assert "more than once" in response.json()["detail"], response.text
    assert api.client.get("/v1/robots/R1/history?frame=a&limit=2", headers=read).status_code == 200


def test_control_characters_in_a_query_parameter_are_422_problems(api: Api) -> None:
    """PostgreSQL refuses a NUL in text; no frame holds a control character."""
    api.upload("R1")
    for frame in ("a\x00b", "a\x1fb", "lidar\n", "\x7f"):
        response = api.client.get(
            "/v1/robots/R1/history", params={"frame": frame}, headers=api.headers("read")
        )
        assert response.status_code == 422, (frame, response.text)
        assert problem_type(response) == "invalid-request"


def test_cursors_holding_what_no_cursor_holds_are_400_problems(api: Api) -> None:
    """Well-formed cursors, so that each reaches the key it carries: a NUL (PostgreSQL), a row id
    that is no integer or is past 64 bits (SQLite), an instant outside UTC's range."""
    from service.pagination import encode_cursor

    api.upload("R1")
    instant = "2026-01-01T00:00:00+00:00"
    robots = [encode_cursor("robots", "R\x001"), encode_cursor("robots", "R1") + "\x00"]
    cases = {
        "/v1/robots": robots,
        "/v1/fleet": robots,
        "/v1/robots/R1/history": [
            encode_cursor("history", instant, "1" * 31),
            encode_cursor("history", instant, str(2**63)),
            encode_cursor("history", instant, "²"),
            encode_cursor("history", instant, "1\x00"),
            encode_cursor("history", instant + "\x00", "1"),
            encode_cursor("history", "0001-01-01T00:00:00+23:59", "1"),
        ],
        "/v1/runs": [
            encode_cursor("runs", instant + "\x00", "0" * 32),
            encode_cursor("runs", "9999-12-31T23:59:59-23:59", "0" * 32),
            encode_cursor("runs", instant, "0" * 31 + "\x00"),
        ],
    }
    for path, cursors in cases.items():
        for cursor in cursors:
            response = api.client.get(path, params={"cursor": cursor}, headers=api.headers("read"))
            assert response.status_code == 400, (path, cursor, response.text)
            assert problem_type(response) == "invalid-cursor"
