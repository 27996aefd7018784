"""Upload streaming at the ASGI level, where the test controls the body chunk by chunk: a large
body passes with bounded memory; a client that disconnects or lies about Content-Length leaves no
run and no file. (TestClient reads a request body whole, so these drive the app directly.)"""

from __future__ import annotations

import contextlib
import hashlib
import socket
import time
import tracemalloc
import uuid
from collections.abc import AsyncIterator, Iterator, MutableMapping
from pathlib import Path
from typing import Any

import anyio
import httpx
import pytest
from fastapi import FastAPI

from service.app import create_app, start_services
from service.deps import Services
from service.settings import Settings
from service.storage import LocalStorage
from tests.service.conftest import make_keys, recording, running_api
from tests.service.uploads import new_upload

MIB = 1024 * 1024


@pytest.fixture
def app_and_key(tmp_path: Path) -> Iterator[tuple[FastAPI, Services, str]]:
    # Memory and disconnects do not depend on the database: SQLite only.
    settings = Settings(data_dir=tmp_path, max_upload_bytes=1024 * MIB)
    app = create_app(settings)
    services = start_services(settings)
    app.state.services = services
    yield app, services, make_keys(services.db)["upload_r1"]
    services.db.dispose()


def _stored(services: Services) -> list[Path]:
    assert isinstance(services.storage, LocalStorage)
    return sorted(p for p in services.storage.root.rglob("*") if p.is_file())


def _run_count(services: Services) -> int:
    from sqlalchemy import func, select

    from service.models import Run

    with services.db.session() as session:
        return session.scalar(select(func.count()).select_from(Run)) or 0


def test_a_large_upload_streams_with_bounded_memory(
    app_and_key: tuple[FastAPI, Services, str],
) -> None:
    app, services, key = app_and_key
    total, chunk_size = 128 * MIB, 64 * 1024  # uvicorn hands bodies over in ~64 KiB pieces
    chunk = recording(chunk_size)
    expected = hashlib.sha256()
    for _ in range(total // chunk_size):
        expected.update(chunk)

    async def body() -> AsyncIterator[bytes]:
        for _ in range(total // chunk_size):
            yield chunk  # the same object each time: the client side allocates nothing

    async def upload() -> httpx.Response:
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://fleetcal") as client:
            return await client.post(
                "/v1/robots/R1/runs?kind=end_of_line",
                content=body(),
                headers={"X-API-Key": key, "X-Content-SHA256": expected.hexdigest()},
            )

    tracemalloc.start()
    try:
        response = anyio.run(upload)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert response.status_code == 202, response.text
    assert response.json()["upload"] == {
        "size": total,
        "sha256": expected.hexdigest(),
        "format": "mcap",
    }
    # A whole body would be 128 MiB; the app holds a 1 MiB block and its copy at a time
    # (about 3.4 MiB peak measured, interpreter overhead included).
    assert peak < 8 * MIB, f"peak Python allocation {peak / MIB:.1f} MiB"
    stored = [p for p in _stored(services) if ".tmp" not in p.parts]
    assert len(stored) == 1 and stored[0].stat().st_size == total


async def _raw_asgi(
    app: FastAPI, headers: dict[str, str], messages: list[dict[str, Any]]
) -> dict[str, Any]:
    """Call the app with exactly these receive() messages; return the response start."""
    pending = list(messages)
    sent: list[MutableMapping[str, Any]] = []

    async def receive() -> dict[str, Any]:
        if pending:
            return pending.pop(0)
        await anyio.sleep_forever()
        raise AssertionError("unreachable")

    async def send(message: MutableMapping[str, Any]) -> None:
        sent.append(message)

    scope = {
        "type": "http",
        "asgi": {"version": "3.0"},
        "http_version": "1.1",
        "method": "POST",
        "scheme": "http",
        "path": "/v1/robots/R1/runs",
        "raw_path": b"/v1/robots/R1/runs",
        "query_string": b"kind=end_of_line",
        "root_path": "",
        "client": ("127.0.0.1", 1),
        "server": ("fleetcal", 80),
        "headers": [(k.lower().encode(), v.encode()) for k, v in headers.items()],
    }
    await app(scope, receive, send)
    return dict(next(m for m in sent if m["type"] == "http.response.start"))


def test_a_client_disconnect_mid_upload_leaves_nothing(
    app_and_key: tuple[FastAPI, Services, str],
) -> None:
    app, services, key = app_and_key
    part = recording(3 * MIB)  # more than one block: something was written before the drop
    messages: list[dict[str, Any]] = [
        {"type": "http.request", "body": part, "more_body": True},
        {"type": "http.request", "body": part, "more_body": True},
        {"type": "http.disconnect"},
    ]
    anyio.run(_raw_asgi, app, {"x-api-key": key}, messages)
    assert _run_count(services) == 0
    assert _stored(services) == []


def test_a_body_shorter_than_its_content_length_is_refused(
    app_and_key: tuple[FastAPI, Services, str],
) -> None:
    app, services, key = app_and_key
    body = recording(5000)
    messages: list[dict[str, Any]] = [{"type": "http.request", "body": body, "more_body": False}]
    start = anyio.run(_raw_asgi, app, {"x-api-key": key, "content-length": "9000"}, messages)
    assert start["status"] == 400
    assert _run_count(services) == 0 and _stored(services) == []


def test_a_non_numeric_content_length_is_refused(
    app_and_key: tuple[FastAPI, Services, str],
) -> None:
    app, services, key = app_and_key
    messages: list[dict[str, Any]] = [
        {"type": "http.request", "body": recording(), "more_body": False}
    ]
    start = anyio.run(_raw_asgi, app, {"x-api-key": key, "content-length": "12abc"}, messages)
    assert start["status"] == 400
    assert _run_count(services) == 0 and _stored(services) == []


def test_uploads_left_by_a_killed_process_are_swept_at_start(tmp_path: Path) -> None:
    import os
    import time

    storage_root = tmp_path / "storage"
    (storage_root / ".tmp").mkdir(parents=True)
    killed, older = storage_root / ".tmp" / "new.part", storage_root / ".tmp" / "old.part"
    killed.write_bytes(b"half an upload, its writer gone (no lock)")
    older.write_bytes(b"half an upload")
    old = time.time() - 7 * 3600
    os.utime(older, (old, old))
    in_progress = LocalStorage(storage_root).begin_upload("recordings/R1/run")  # holds its lock
    in_progress.write(b"an upload in progress in another process")
    services = start_services(Settings(data_dir=tmp_path))
    services.db.dispose()
    assert not killed.exists() and not older.exists()
    in_progress.commit()
    assert services.storage.exists("recordings/R1/run")


def test_an_upload_lands_in_s3_storage(settings: Settings, s3_env: None, s3_endpoint: str) -> None:
    import boto3

    bucket = f"fleetcal-{uuid.uuid4().hex[:12]}"
    boto3.client("s3", endpoint_url=s3_endpoint).create_bucket(Bucket=bucket)
    s3_settings = settings.model_copy(
        update={
            "storage_url": f"s3://{bucket}/recordings-eu",
            "s3_endpoint_url": s3_endpoint,
            "s3_part_size_bytes": 5 * MIB,
            "max_upload_bytes": 64 * MIB,
        }
    )
    body = recording(12 * MIB)
    with running_api(s3_settings) as api:
        response = api.upload("R1", body, **{"X-Content-SHA256": hashlib.sha256(body).hexdigest()})
        assert response.status_code == 202, response.text
        refused = api.upload("R1", b"not a recording" * 1000)
        assert refused.status_code == 415
        run = api.client.get(response.headers["location"], headers=api.headers("read")).json()
        with api.services.db.session() as session:
            from service.models import Run

            row = session.get(Run, uuid.UUID(run["id"]))
            assert row is not None
        with api.services.storage.open(row.storage_key) as stream:
            assert stream.read() == body
        client = boto3.client("s3", endpoint_url=s3_endpoint)
        keys = [o["Key"] for o in client.list_objects_v2(Bucket=bucket).get("Contents", [])]
        assert keys == [f"recordings-eu/{row.storage_key}"]
        assert client.list_multipart_uploads(Bucket=bucket).get("Uploads", []) == []


@contextlib.contextmanager
def _live_server(app: FastAPI) -> Iterator[int]:
    """The app under a real uvicorn server on loopback, in a thread."""
    import threading

    import uvicorn

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = int(probe.getsockname()[1])
    server = uvicorn.Server(
        uvicorn.Config(app, host="127.0.0.1", port=port, log_level="error", lifespan="off")
    )
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 10
    while not server.started:
        assert time.monotonic() < deadline, "uvicorn did not start"
        time.sleep(0.02)
    try:
        yield port
    finally:
        server.should_exit = True
        thread.join(10)


def test_a_real_connection_dropped_mid_upload_leaves_nothing(
    app_and_key: tuple[FastAPI, Services, str],
) -> None:
    app, services, key = app_and_key
    with _live_server(app) as port:
        with socket.create_connection(("127.0.0.1", port)) as client:
            client.sendall(
                b"POST /v1/robots/R1/runs?kind=end_of_line HTTP/1.1\r\nHost: fleetcal\r\n"
                + f"X-API-Key: {key}\r\nContent-Length: {64 * MIB}\r\n\r\n".encode()
                + recording(3 * MIB)
            )
            deadline = time.monotonic() + 10
            while not _stored(services):  # the upload has begun writing
                assert time.monotonic() < deadline, "the upload never started"
                time.sleep(0.02)
        # The client is gone; the server notices, aborts, and answers no one.
        deadline = time.monotonic() + 10
        while _stored(services):
            assert time.monotonic() < deadline, f"left behind: {_stored(services)}"
            time.sleep(0.05)
        assert _run_count(services) == 0


def test_recordings_no_run_points_at_are_swept_at_start(tmp_path: Path) -> None:
    """A process killed between moving an upload into place and committing its run leaves an
    orphan recording; the next start removes it once it is old, and nothing a run needs."""
    import os

    from service import repository

    services = start_services(Settings(data_dir=tmp_path))
    kept_key = repository.recording_key("R1", uuid.uuid4())
    with services.db.transaction() as session:
        repository.record_upload(
            session,
            new_upload(run_id=uuid.UUID(kept_key.rsplit("/", 1)[-1]), storage_key=kept_key),
            create_robot=True,
        )
    services.db.dispose()
    storage = services.storage
    assert isinstance(storage, LocalStorage)
    orphan, fresh = (
        repository.recording_key("R1", uuid.uuid4()),
        repository.recording_key("R2", uuid.uuid4()),
    )
    foreign = "recordings/R1/not-a-run-id"
    old = time.time() - 7 * 3600
    for key in (kept_key, orphan, fresh, foreign):
        pending = storage.begin_upload(key)
        pending.write(b"a recording")
        pending.commit()
        if key != fresh:
            os.utime(storage.path(key), (old, old))

    start_services(Settings(data_dir=tmp_path)).db.dispose()

    assert storage.exists(kept_key) and storage.exists(fresh)
    assert storage.exists(foreign)  # not a key the service writes: left alone
    assert not storage.exists(orphan)
