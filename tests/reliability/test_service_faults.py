"""Faults around the service, on SQLite and PostgreSQL: the API killed with SIGKILL in the middle
of an upload (no run, no recording; its temporary file is swept at the next start), the storage
running out of space during an upload (507, nothing kept, uploads work again once space is freed),
and PostgreSQL restarted while a run is being calibrated (the run completes or is retried, never
stays `running`; requests during the outage get 503 problems)."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import psycopg
import pytest

from service.db import Database
from service.models import RunStatus
from service.settings import Settings
from service.storage import LocalStorage
from tests.conftest import unavailable
from tests.reliability.harness import (
    free_port,
    processes,
    run_row,
    start_api,
    stored_results,
    wait_for,
)
from tests.service.conftest import make_keys, problem_type, recording, running_api
from tests.workers.runs import enqueue, running_worker

MIB = 1024 * 1024


def files_under(root: Path) -> list[Path]:
    return sorted(p for p in root.rglob("*") if p.is_file())


def run_count(db: Database) -> int:
    from sqlalchemy import func, select

    from service.models import Run

    with db.session() as session:
        return int(session.scalar(select(func.count()).select_from(Run)) or 0)


# -- the API killed mid-upload --------------------------------------------------------------------


def test_the_api_killed_mid_upload_leaves_no_run_and_no_recording(
    settings: Settings, tmp_path: Path
) -> None:
    db = Database.from_settings(settings)
    key = make_keys(db)["upload_r1"]
    storage = LocalStorage(Path(settings.resolved_storage_url.removeprefix("file://")))
    body = recording(4 * MIB)
    with processes() as started:
        api, url = start_api(settings, tmp_path / "api-1.log")
        started.append(api)
        port = int(url.rsplit(":", 1)[1])
        with socket.create_connection(("127.0.0.1", port)) as client:
            client.sendall(
                b"POST /v1/robots/R1/runs?kind=end_of_line HTTP/1.1\r\nHost: fleetcal\r\n"
                + f"X-API-Key: {key}\r\nContent-Length: {len(body)}\r\n\r\n".encode()
            )
            client.sendall(body[: 3 * MIB // 2])

            def writing() -> bool:
                parts = storage.temporary_uploads()
                return bool(parts) and parts[0].stat().st_size >= MIB

            wait_for("the API to write the upload", writing, timeout=120)
            api.kill()
        assert run_count(db) == 0
        assert [p.name for p in files_under(storage.root / "recordings")] == []
        (left,) = storage.temporary_uploads()  # the kill left its temporary file, invisible
        # Long after: the next start sweeps temporary uploads older than its limit.
        an_hour_ago = time.time() - 3600
        os.utime(left, (an_hour_ago, an_hour_ago))
        api, url = start_api(settings, tmp_path / "api-2.log", FLEETCAL_STALE_UPLOAD_SECONDS="600")
        started.append(api)
        assert storage.temporary_uploads() == []
        assert files_under(storage.root) == []
        response = httpx.post(
            f"{url}/v1/robots/R1/runs?kind=end_of_line",
            content=recording(),
            headers={"X-API-Key": key},
            timeout=60,
        )
        assert response.status_code == 202, response.text
        assert run_count(db) == 1
    db.dispose()


# -- disk full ------------------------------------------------------------------------------------

SMALL_FS = 3 * MIB


def can_mount_in_a_namespace() -> str | None:
    """Why a private tmpfs cannot be mounted here, or None if it can."""
    if shutil.which("unshare") is None:
        return "unshare(1) is missing"
    done = subprocess.run(
        [
            "unshare",
            "--user",
            "--map-root-user",
            "--mount",
            "sh",
            "-c",
            "mount -t tmpfs -o size=64k tmpfs /mnt",
        ],
        capture_output=True,
        text=True,
    )
    return None if done.returncode == 0 else f"no user and mount namespaces: {done.stderr}"


def test_a_full_storage_refuses_uploads_with_507_and_recovers(
    settings: Settings, tmp_path: Path
) -> None:
    """The storage is a 3 MiB tmpfs of the API's own mount namespace (no root needed): the writes
    really fail with ENOSPC. The test reaches that filesystem through /proc/<pid>/root."""
    reason = can_mount_in_a_namespace()
    if reason is not None:
        pytest.skip(reason)
    root = tmp_path / "small-storage"
    root.mkdir()
    settings = settings.model_copy(update={"storage_url": root.as_uri()})
    db = Database.from_settings(settings)
    headers = {"X-API-Key": make_keys(db)["admin"]}
    mount = f'mount -t tmpfs -o size={SMALL_FS} tmpfs "$0" && exec "$@"'
    wrap = ["unshare", "--user", "--map-root-user", "--mount", "sh", "-c", mount, str(root)]
    with processes() as started:
        api, url = start_api(settings, tmp_path / "api.log", wrap=wrap)
        started.append(api)
        seen = Path(f"/proc/{api.popen.pid}/root") / root.relative_to("/")
        assert os.statvfs(seen).f_blocks * os.statvfs(seen).f_frsize <= SMALL_FS

        def upload(size: int) -> httpx.Response:
            return httpx.post(
                f"{url}/v1/robots/R1/runs?kind=end_of_line",
                content=recording(size),
                headers=headers,
                timeout=60,
            )

        assert upload(MIB).status_code == 202
        kept = files_under(seen)
        # Fill the filesystem but for 256 KiB, then upload 1 MiB.
        free = os.statvfs(seen).f_bavail * os.statvfs(seen).f_frsize
        filler = seen / "filler"
        with filler.open("wb") as sink:
            sink.write(b"\0" * max(free - 256 * 1024, 0))
        full = upload(MIB)
        assert full.status_code == 507, full.text
        assert problem_type(full) == "insufficient-storage"
        assert "retry when space is freed" in full.json()["detail"]
        assert files_under(seen) == sorted([*kept, filler]), "nothing partial was kept"
        assert run_count(db) == 1
        assert httpx.get(f"{url}/healthz", timeout=30).status_code == 200
        filler.unlink()
        again = upload(MIB)
        assert again.status_code == 202, again.text
        assert run_count(db) == 2
    db.dispose()


# -- PostgreSQL restarted during a run ------------------------------------------------------------


def _postgres_bin() -> Path | None:
    found = sorted(Path("/usr/lib/postgresql").glob("*/bin/pg_ctl"))
    return found[-1].parent if found else None


def pg(command: list[str], *, check: bool = True) -> None:
    """Run pg_ctl. No pipes: the server it starts would inherit them and hold them open."""
    subprocess.run(command, check=check, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


@pytest.fixture
def private_postgres() -> Iterator[tuple[str, list[str]]]:
    """A PostgreSQL server of this test's own (initdb in a scratch folder, a free port): restarting
    it disturbs no other test. Yields its URL and the pg_ctl command line (without the action)."""
    bindir = _postgres_bin()
    if bindir is None:
        unavailable("no PostgreSQL server binaries in /usr/lib/postgresql")
    as_user: list[str] = []
    scratch = Path(tempfile.mkdtemp(prefix="fleetcal-pg-"))
    if os.geteuid() == 0:  # initdb refuses to run as root
        shutil.chown(scratch, "postgres")
        as_user = ["runuser", "-u", "postgres", "--"]
    data, port = scratch / "data", free_port()
    subprocess.run(
        [*as_user, str(bindir / "initdb"), "-D", str(data), "-A", "trust", "-U", "postgres"],
        check=True,
        capture_output=True,
    )
    options = f"-p {port} -k {scratch} -c listen_addresses=127.0.0.1 -c fsync=off"
    pg_ctl = [*as_user, str(bindir / "pg_ctl"), "-D", str(data), "-o", options, "-w"]
    pg_ctl += ["-l", str(scratch / "log")]
    pg([*pg_ctl, "start"])
    try:
        with psycopg.connect(
            f"postgresql://postgres@127.0.0.1:{port}/postgres", autocommit=True
        ) as admin:
            admin.execute("CREATE DATABASE fleetcal")
        url = f"postgresql+psycopg://postgres@127.0.0.1:{port}/fleetcal"
        db = Database.from_settings(Settings(database_url=url))
        db.upgrade()
        db.dispose()
        yield url, pg_ctl
    finally:
        pg([*pg_ctl, "-m", "immediate", "stop"], check=False)
        shutil.rmtree(scratch, ignore_errors=True)


@pytest.mark.postgres
def test_postgres_restarted_during_a_run(
    private_postgres: tuple[str, list[str]], tmp_path: Path
) -> None:
    url, pg_ctl = private_postgres
    settings = Settings(
        data_dir=tmp_path / "data",
        database_url=url,
        storage_url=(tmp_path / "storage").as_uri(),
        run_lease_seconds=2,
        migrate_on_start=False,
    )
    with running_api(settings) as api:
        db = api.services.db
        run_id = enqueue(db, config={"sleep": 1.0})
        with running_worker(settings):
            wait_for("the run to start", lambda: run_row(db, run_id).status == RunStatus.RUNNING)
            pg([*pg_ctl, "-m", "fast", "stop"])
            # While it is down: answers are 503 problems, and an upload keeps nothing.
            for path in ("/v1/runs", f"/v1/runs/{run_id}"):
                down = api.client.get(path, headers=api.headers("admin"))
                assert down.status_code == 503, down.text
                assert problem_type(down) == "database-unavailable"
            assert problem_type(api.client.get("/readyz")) == "not-ready"
            upload = api.upload("R1", recording())
            assert upload.status_code == 503 and problem_type(upload) == "database-unavailable"
            assert files_under(api.storage.root) == []
            # The outage outlasts the run's lease and its one-second calibration.
            time.sleep(3 * settings.run_lease_seconds)
            pg([*pg_ctl, "start"])
            final = (RunStatus.SUCCEEDED, RunStatus.FAILED)
            wait_for("the run to end", lambda: run_row(db, run_id).status in final, timeout=120)
        run = run_row(db, run_id)
        assert run.status == RunStatus.SUCCEEDED, run.error
        assert run.attempts in (1, 2), "completed, or retried once after the outage"
        assert stored_results(db, run_id)[0] == 1
        assert api.client.get("/readyz").status_code == 200
        assert api.upload("R1", recording()).status_code == 202
