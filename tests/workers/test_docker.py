"""The distributed deployment in `docker/`, as far as it can be checked without a Docker engine:
the compose file's services and wiring, the image's entrypoint, and each entrypoint role (`migrate`,
`api`, `worker`) run as a plain process against this machine's PostgreSQL."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml

from service.db import Database
from service.models import RunStatus
from service.settings import Settings
from tests.service.conftest import scratch_pg_database
from tests.workers.jobs import SCRIPTED
from tests.workers.runs import ROOT, enqueue, entrypoint_env, run_row, wait_for

DOCKER = ROOT / "docker"
ENTRYPOINT = DOCKER / "entrypoint.sh"


@pytest.fixture(scope="module")
def compose() -> dict[str, Any]:
    document = yaml.safe_load((DOCKER / "compose.yaml").read_text())
    assert isinstance(document, dict)
    return document


def test_compose_runs_postgres_s3_migrate_api_and_workers(compose: dict[str, Any]) -> None:
    services = compose["services"]
    assert {"postgres", "minio", "create-bucket", "migrate", "api", "worker"} <= services.keys()
    for role in ("migrate", "api", "worker"):
        service = services[role]
        assert service["build"] == {"context": "..", "dockerfile": "docker/Dockerfile"}
        assert service["command"] == [role]
        env = service["environment"]
        assert env["FLEETCAL_DATABASE_URL"].startswith("postgresql+psycopg://")
        assert "@postgres:5432/" in env["FLEETCAL_DATABASE_URL"]
        assert env["FLEETCAL_STORAGE_URL"].startswith("s3://fleetcal")
        assert env["FLEETCAL_S3_ENDPOINT_URL"] == "http://minio:9000"
        assert (
            env["AWS_SECRET_ACCESS_KEY"] == services["minio"]["environment"]["MINIO_ROOT_PASSWORD"]
        )
    assert services["migrate"]["environment"]["FLEETCAL_MIGRATE_ON_START"] == "true"
    for role in ("api", "worker"):
        assert services[role]["environment"]["FLEETCAL_MIGRATE_ON_START"] == "false"
        assert services[role]["depends_on"]["migrate"] == {
            "condition": "service_completed_successfully"
        }
        assert services[role]["depends_on"]["create-bucket"] == {
            "condition": "service_completed_successfully"
        }
    assert services["migrate"]["depends_on"]["postgres"] == {"condition": "service_healthy"}
    assert services["worker"]["deploy"]["replicas"] >= 2
    # A stopping worker needs its grace period before Docker kills it.
    grace = int(services["worker"]["environment"]["FLEETCAL_SHUTDOWN_GRACE"])
    assert int(services["worker"]["stop_grace_period"].rstrip("s")) > grace
    assert "8000:8000" in services["api"]["ports"]


def test_the_image_runs_the_entrypoint() -> None:
    dockerfile = (DOCKER / "Dockerfile").read_text()
    assert "COPY docker/entrypoint.sh /usr/local/bin/fleetcal-entrypoint" in dockerfile
    assert 'ENTRYPOINT ["fleetcal-entrypoint"]' in dockerfile
    assert "libusb-1.0-0" in dockerfile, "open3d cannot load without it"
    assert os.access(ENTRYPOINT, os.X_OK)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@pytest.fixture(scope="module")
def migrated_pg() -> Iterator[str]:
    """A PostgreSQL database migrated by the `migrate` entrypoint (shared by this module)."""
    with scratch_pg_database() as url:
        env = entrypoint_env(FLEETCAL_DATABASE_URL=url)
        done = subprocess.run(
            [str(ENTRYPOINT), "migrate"], env=env, capture_output=True, text=True, timeout=120
        )
        assert done.returncode == 0, done.stderr
        assert "at revision" in done.stdout
        yield url


@pytest.mark.postgres
def test_migrate_brings_an_empty_database_to_the_newest_schema(migrated_pg: str) -> None:
    db = Database.from_settings(Settings(database_url=migrated_pg))
    try:
        assert db.migrations_current()
    finally:
        db.dispose()


@pytest.mark.postgres
@pytest.mark.slow
def test_api_serves_until_sigterm(migrated_pg: str, tmp_path: Path) -> None:
    port = free_port()
    env = entrypoint_env(
        FLEETCAL_DATABASE_URL=migrated_pg,
        FLEETCAL_STORAGE_URL=(tmp_path / "storage").as_uri(),
        FLEETCAL_MIGRATE_ON_START="false",
        FLEETCAL_HOST="127.0.0.1",
        FLEETCAL_PORT=str(port),
    )
    api = subprocess.Popen(
        [str(ENTRYPOINT), "api"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:

        def ready() -> bool:
            assert api.poll() is None, api.communicate()[1]
            try:
                return httpx.get(f"http://127.0.0.1:{port}/readyz").status_code == 200
            except httpx.TransportError:
                return False

        wait_for("the API", ready, timeout=120)
        api.send_signal(signal.SIGTERM)
        out, err = api.communicate(timeout=60)
    finally:
        if api.poll() is None:
            api.kill()
    assert api.returncode == 0, err
    assert "admin key" in out and "fck_" in out, "the first start prints an admin key"


@pytest.mark.postgres
@pytest.mark.slow
def test_worker_calibrates_queued_runs_until_sigterm(migrated_pg: str, tmp_path: Path) -> None:
    settings = Settings(database_url=migrated_pg)
    db = Database.from_settings(settings)
    run_id = enqueue(db)
    env = entrypoint_env(
        FLEETCAL_DATABASE_URL=migrated_pg,
        FLEETCAL_STORAGE_URL=(tmp_path / "storage").as_uri(),
        FLEETCAL_MIGRATE_ON_START="false",
        FLEETCAL_WORKER_CONCURRENCY="1",
    )
    worker = subprocess.Popen(
        [str(ENTRYPOINT), "worker", "--job", SCRIPTED],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        wait_for("the run", lambda: run_row(db, run_id).status == RunStatus.SUCCEEDED, 120)
        worker.send_signal(signal.SIGTERM)
        _, err = worker.communicate(timeout=60)
    finally:
        if worker.poll() is None:
            worker.kill()
        db.dispose()
    assert worker.returncode == 0, err
    assert "SIGTERM" in err and "stopped" in err
