"""The embedded service: the API (uvicorn) and in-process workers in one process, on the same
settings, as `fleetcal serve` and `fleetcal demo` run them.

uvicorn serves from a thread (it installs no signal handlers off the main thread), so the caller's
main thread keeps Ctrl-C and SIGTERM and decides when everything stops.
"""

from __future__ import annotations

import dataclasses
import errno
import logging
import socket
import threading
import time
from types import TracebackType

import uvicorn
from sqlalchemy import func, select

from service.app import create_app
from service.auth import create_key
from service.db import Database
from service.models import ApiKey, Scope
from service.server import http_protocol
from service.settings import Settings
from service.startup import StartupError, open_database, open_storage
from workers.worker import Worker, WorkerOptions

log = logging.getLogger(__name__)

STARTUP_TIMEOUT_S = 120


def bootstrap_admin_key(db: Database) -> str | None:
    """Create an admin key if the database has no key at all; return its secret (None if keys
    exist). Under `BEGIN IMMEDIATE` on SQLite and with the table locked on PostgreSQL, so two
    processes starting together cannot both create one."""
    with db.transaction() as session:
        if db.engine.dialect.name == "postgresql":
            session.execute(select(func.pg_advisory_xact_lock(0x666C6B)))
        if session.scalar(select(func.count()).select_from(ApiKey)):
            return None
        key = create_key(session, [Scope.ADMIN], name="first admin (created by fleetcal serve)")
    return key.secret


def first_admin_key(settings: Settings) -> str | None:
    """`bootstrap_admin_key` on the settings' database."""
    db = Database.from_settings(settings)
    try:
        return bootstrap_admin_key(db)
    finally:
        db.dispose()


class EmbeddedService:
    """`with EmbeddedService(settings, ...) as service:` the API answers at `service.url` and
    `workers` pipeline processes calibrate the queued runs; leaving the block stops both (running
    runs get `options.shutdown_grace` to finish, then go back to the queue)."""

    def __init__(
        self,
        settings: Settings,
        *,
        host: str = "127.0.0.1",
        port: int = 8000,
        workers: int = 1,
        options: WorkerOptions | None = None,
        access_log: bool = False,
    ) -> None:
        self.settings = settings
        self.host = host
        self.port = port
        self.workers = workers
        self.options = options or WorkerOptions()
        self.access_log = access_log
        self.worker: Worker | None = None
        self._threads: list[threading.Thread] = []
        self._server: uvicorn.Server | None = None
        self._socket: socket.socket | None = None

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}"

    def prepare(self, *, migrate: bool | None = None) -> None:
        """Check everything the start needs, so that it fails before anything is created: the
        port is bound (first: a busy port must not leave a new database behind), the database
        answers and is migrated (`migrate`, default the settings' `migrate_on_start`), and the
        storage takes writes. Raises `StartupError`."""
        if self._socket is not None:
            return
        migrate = self.settings.migrate_on_start if migrate is None else migrate
        sock = _bind(self.host, self.port)
        try:
            open_database(self.settings, migrate=migrate).dispose()
            open_storage(self.settings)
        except BaseException:
            sock.close()
            raise
        self._socket = sock
        self.port = sock.getsockname()[1]

    def __enter__(self) -> EmbeddedService:
        self.prepare()
        assert self._socket is not None
        config = uvicorn.Config(
            create_app(self.settings),
            log_level="warning",
            access_log=self.access_log,
            lifespan="on",
            http=http_protocol(),
        )
        self._server = uvicorn.Server(config)
        server_thread = threading.Thread(
            target=self._server.run,
            kwargs={"sockets": [self._socket]},
            name="fleetcal-api",
            daemon=True,
        )
        server_thread.start()
        self._threads.append(server_thread)
        deadline = time.monotonic() + STARTUP_TIMEOUT_S
        while not self._server.started:
            if not server_thread.is_alive() or time.monotonic() > deadline:
                self._stop()
                raise RuntimeError("the API did not start; see the log above")
            time.sleep(0.05)
        if self.workers > 0:
            self.worker = Worker(
                self.settings, dataclasses.replace(self.options, concurrency=self.workers)
            )
            worker_thread = threading.Thread(
                target=self.worker.run, name="fleetcal-worker", daemon=True
            )
            worker_thread.start()
            self._threads.append(worker_thread)
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self._stop()

    def _stop(self) -> None:
        # Workers first: a run finishing in the grace period can still be stored and read.
        if self.worker is not None:
            self.worker.request_stop()
        if self._server is not None:
            self._server.should_exit = True
        for thread in reversed(self._threads):
            thread.join()
        if self._socket is not None:
            self._socket.close()


_BIND_HINTS = {
    errno.EADDRINUSE: "another process listens there: stop it or choose a free port with --port",
    errno.EADDRNOTAVAIL: "this machine has no such address: choose another --host",
    errno.EACCES: "ports below 1024 need privileges: choose --port 1024 or above",
}


def _bind(host: str, port: int) -> socket.socket:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except (OSError, OverflowError) as err:
        sock.close()
        code = err.errno if isinstance(err, OSError) else None
        reason = err.strerror if isinstance(err, OSError) and err.strerror else str(err)
        hint = _BIND_HINTS.get(code or 0, "check --host and --port")
        raise StartupError(f"cannot listen on {host}:{port}: {reason}; {hint}") from None
    sock.listen(128)
    sock.set_inheritable(True)
    return sock
