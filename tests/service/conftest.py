"""Fixtures for the service tests: every database test runs on SQLite and on PostgreSQL.

Each test session (each xdist worker) gets its own PostgreSQL database `fleetcal_test_<hex>`,
migrated once and emptied before every test; SQLite tests copy a migrated template file.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import psycopg
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import func, select, text

from service.app import create_app
from service.auth import create_key
from service.db import Database
from service.deps import Services
from service.models import Base, Run, Scope
from service.settings import Settings
from service.storage import LocalStorage
from tests.conftest import unavailable

PG_ADMIN_DSN = os.environ.get(
    "FLEETCAL_TEST_PG_ADMIN_DSN", "postgresql://postgres@127.0.0.1:5432/postgres"
)
MCAP_MAGIC = b"\x89MCAP0\r\n"


def pg_url(database: str) -> str:
    info = psycopg.conninfo.conninfo_to_dict(PG_ADMIN_DSN)
    user = info.get("user", "postgres")
    host, port = info.get("host", "127.0.0.1"), info.get("port", "5432")
    return f"postgresql+psycopg://{user}@{host}:{port}/{database}"


@contextlib.contextmanager
def scratch_pg_database() -> Iterator[str]:
    """A new, empty PostgreSQL database (dropped afterwards); skips if the server is down (fails
    under CI=true)."""
    try:
        admin = psycopg.connect(PG_ADMIN_DSN, autocommit=True, connect_timeout=3)
    except psycopg.OperationalError as err:
        unavailable(f"PostgreSQL at {PG_ADMIN_DSN} is unreachable ({err}); CI runs these")
    name = f"fleetcal_test_{uuid.uuid4().hex[:12]}"
    try:
        admin.execute(f'CREATE DATABASE "{name}"')
        yield pg_url(name)
    finally:
        admin.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')
        admin.close()


@pytest.fixture(params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def unmigrated_db(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Database]:
    """An empty database on each engine, no migration applied (the migration tests apply them)."""
    if request.param == "sqlite":
        db = Database.from_settings(Settings(database_url=f"sqlite:///{tmp_path / 'm.db'}"))
        yield db
        db.dispose()
        return
    with scratch_pg_database() as url:
        db = Database.from_settings(Settings(database_url=url))
        yield db
        db.dispose()


@pytest.fixture(scope="session")
def pg_session_url() -> Iterator[str]:
    with scratch_pg_database() as url:
        db = Database.from_settings(Settings(database_url=url))
        db.upgrade()
        db.dispose()
        yield url


@pytest.fixture(scope="session")
def sqlite_template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("template") / "fleetcal.db"
    db = Database.from_settings(Settings(database_url=f"sqlite:///{path}"))
    db.upgrade()
    db.dispose()
    return path


@pytest.fixture(params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def db_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """A migrated, empty database of each kind."""
    if request.param == "sqlite":
        target = tmp_path / "fleetcal.db"
        shutil.copyfile(request.getfixturevalue("sqlite_template"), target)
        return f"sqlite:///{target}"
    url: str = request.getfixturevalue("pg_session_url")
    db = Database.from_settings(Settings(database_url=url))
    tables = ", ".join(f'"{t.name}"' for t in Base.metadata.sorted_tables)
    with db.engine.begin() as connection:
        connection.execute(text(f"TRUNCATE {tables}"))
    db.dispose()
    return url


@pytest.fixture
def settings(db_url: str, tmp_path: Path) -> Settings:
    return Settings(
        data_dir=tmp_path / "data",
        database_url=db_url,
        storage_url=(tmp_path / "storage").as_uri(),
        max_upload_bytes=2 * 1024 * 1024,
        migrate_on_start=False,  # the fixtures migrated it; test_app checks migration on start
    )


@pytest.fixture(scope="session")
def s3_endpoint() -> Iterator[str]:
    """An S3-compatible server on loopback (moto's), as MinIO would be in a deployment."""
    pytest.importorskip("boto3", reason="S3 storage needs boto3")
    moto_server = pytest.importorskip("moto.server", reason="moto[server] provides the S3 server")
    server = moto_server.ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)
    server.start()
    host, port = server.get_host_and_port()
    yield f"http://{host}:{port}"
    server.stop()


@pytest.fixture
def s3_env(monkeypatch: pytest.MonkeyPatch) -> None:
    for name, value in {
        "AWS_ACCESS_KEY_ID": "test",
        "AWS_SECRET_ACCESS_KEY": "test",
        "AWS_DEFAULT_REGION": "us-east-1",
    }.items():
        monkeypatch.setenv(name, value)


@dataclass
class Api:
    """A running app with a client and one key of each kind (as ready-made headers)."""

    client: TestClient
    services: Services
    keys: dict[str, str]

    def headers(self, key: str, **extra: str) -> dict[str, str]:
        return {"X-API-Key": self.keys[key], **extra}

    @property
    def storage(self) -> LocalStorage:
        assert isinstance(self.services.storage, LocalStorage)
        return self.services.storage

    def run_count(self) -> int:
        with self.services.db.session() as session:
            return session.scalar(select(func.count()).select_from(Run)) or 0

    def stored_files(self) -> list[Path]:
        """Every file in storage: recordings and unfinished uploads alike."""
        return sorted(p for p in self.storage.root.rglob("*") if p.is_file())

    def upload(
        self,
        robot: str = "R1",
        body: bytes | None = None,
        *,
        key: str = "admin",
        kind: str = "end_of_line",
        **headers: str,
    ) -> Any:
        content = recording() if body is None else body
        return self.client.post(
            f"/v1/robots/{robot}/runs?kind={kind}",
            content=content,
            headers=self.headers(key, **headers),
        )


def recording(size: int = 4096, seed: int = 0) -> bytes:
    """Bytes that pass the upload's magic-byte check (an MCAP header, then filler)."""
    pattern = bytes((seed + i) % 251 for i in range(251))
    filler = pattern * ((size - len(MCAP_MAGIC)) // 251 + 1)
    return MCAP_MAGIC + filler[: size - len(MCAP_MAGIC)]


def make_keys(db: Database) -> dict[str, str]:
    with db.transaction() as session:
        keys = {
            "admin": create_key(session, [Scope.ADMIN]),
            "read": create_key(session, [Scope.READ]),
            "override": create_key(session, [Scope.OVERRIDE], name="line-lead"),
            "upload": create_key(session, [Scope.UPLOAD]),
            "upload_r1": create_key(session, [Scope.UPLOAD], robot_id="R1"),
            "revoked": create_key(session, [Scope.ADMIN]),
        }
    from service.auth import revoke_key

    with db.transaction() as session:
        revoke_key(session, keys["revoked"].id)
    return {name: key.secret for name, key in keys.items()}


@contextlib.contextmanager
def running_api(settings: Settings) -> Iterator[Api]:
    app = create_app(settings)
    with TestClient(app) as client:
        services: Services = app.state.services
        yield Api(client=client, services=services, keys=make_keys(services.db))


@pytest.fixture
def api(settings: Settings) -> Iterator[Api]:
    with running_api(settings) as running:
        yield running


def problem_type(response: Any) -> str:
    """The problem type slug of an error response, checking it is a real problem document."""
    assert response.headers["content-type"].startswith("application/problem+json"), response.text
    body = response.json()
    assert {"type", "title", "status", "detail"} <= body.keys(), body
    assert body["status"] == response.status_code
    prefix = "urn:fleetcal:problem:"
    assert body["type"].startswith(prefix)
    return str(body["type"][len(prefix) :])
