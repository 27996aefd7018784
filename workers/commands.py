"""The workers' commands of the `fleetcal` CLI: `worker` (distributed), `serve` (embedded API and
workers), `demo` (the main job end to end on a fresh machine). Heavy imports stay in the bodies."""

from __future__ import annotations

import contextlib
import logging
import os
import shlex
import signal
import threading
from collections.abc import Callable, Iterator
from datetime import timedelta
from types import FrameType
from typing import TYPE_CHECKING, Annotated

import typer

from service.cli import DataDirOption, settings_for, startup_errors

if TYPE_CHECKING:
    from service.settings import Settings

DEFAULT_GRACE_S = 30.0
DEFAULT_RUN_TIMEOUT_S = 3600.0

GraceOption = Annotated[
    float,
    typer.Option(
        "--shutdown-grace",
        min=0,
        help="Seconds running runs get to finish after SIGTERM/Ctrl-C before they are given back "
        "to the queue (a second signal gives them back at once).",
    ),
]
LogLevelOption = Annotated[str, typer.Option("--log-level", help="debug, info, warning or error.")]


def register(app: typer.Typer) -> None:
    """Add `worker`, `serve` and `demo` to the root `fleetcal` app."""
    app.command("worker")(worker)
    app.command("serve")(serve)
    from workers.demo import demo

    app.command("demo")(demo)


def default_concurrency() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def worker(
    concurrency: Annotated[
        int | None,
        typer.Option(
            "--concurrency",
            "-c",
            min=1,
            help="Pipeline processes, one run each (default: the CPUs this process may use).",
            show_default=False,
        ),
    ] = None,
    data_dir: DataDirOption = None,
    shutdown_grace: GraceOption = DEFAULT_GRACE_S,
    run_timeout: Annotated[
        float,
        typer.Option(
            "--run-timeout",
            min=1,
            help="Seconds an attempt may run before it is stopped and counted as failed.",
        ),
    ] = DEFAULT_RUN_TIMEOUT_S,
    log_level: LogLevelOption = "info",
    job: Annotated[
        str, typer.Option("--job", hidden=True, help="module:function the pool runs (benchmarks).")
    ] = "",
) -> None:
    """Calibrate queued runs until stopped (the distributed worker).

    Point it at the shared database and storage with FLEETCAL_DATABASE_URL and
    FLEETCAL_STORAGE_URL; run any number of workers on any number of machines.
    """
    from service.startup import open_database, open_storage
    from workers.worker import CALIBRATE_JOB, Worker, WorkerOptions

    configure_logging(log_level)
    settings = settings_for(data_dir)
    with startup_errors():
        db = open_database(settings, migrate=settings.migrate_on_start)
        open_storage(settings)
    options = WorkerOptions(
        concurrency=concurrency or default_concurrency(),
        shutdown_grace=timedelta(seconds=shutdown_grace),
        run_timeout=timedelta(seconds=run_timeout),
        job=job or CALIBRATE_JOB,
    )
    running = Worker(settings, options, db=db)
    with stop_signals(running.request_stop):
        running.run()
    db.dispose()


def serve(
    data_dir: DataDirOption = None,
    host: Annotated[str, typer.Option("--host", help="Address to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option("--port", min=0, max=65535)] = 8000,
    workers: Annotated[
        int,
        typer.Option(
            "--workers",
            "-w",
            min=0,
            help="Pipeline processes in this process "
            "(0: API only, for a deployment with separate `fleetcal worker`s).",
        ),
    ] = 1,
    shutdown_grace: GraceOption = DEFAULT_GRACE_S,
    log_level: LogLevelOption = "info",
    access_log: Annotated[bool, typer.Option("--access-log/--no-access-log")] = True,
) -> None:
    """Run the API and workers in one process (the embedded service).

    SQLite and local storage under --data-dir by default: nothing else to start. The first start
    prints an admin key, once.
    """
    from service.startup import shown_database
    from workers.embedded import EmbeddedService, first_admin_key
    from workers.worker import WorkerOptions

    configure_logging(log_level)
    settings = settings_for(data_dir)
    stop = threading.Event()
    options = WorkerOptions(shutdown_grace=timedelta(seconds=shutdown_grace))
    service = EmbeddedService(
        settings, host=host, port=port, workers=workers, options=options, access_log=access_log
    )
    with startup_errors():
        service.prepare()
    # Signals first: a SIGTERM while the service starts must stop it cleanly too.
    with stop_signals(lambda now=False: stop.set()), service:
        typer.echo(
            f"fleetcal API at {service.url} (docs: {service.url}/docs), {workers} worker "
            f"process(es), database {shown_database(settings)}; Ctrl-C stops"
        )
        # Only now, with the API answering: a start that fails must not use up the key's showing.
        print_first_admin_key(first_admin_key(settings), settings)
        stop.wait()
        typer.echo("stopping: running runs finish or go back to the queue")


def print_first_admin_key(secret: str | None, settings: Settings) -> None:
    """Show the admin key a first start created (None: keys existed), with how to make more."""
    if secret is None:
        return
    typer.echo("Created the first admin key; it is shown only this once, store it now:")
    typer.echo(f"  {secret}")
    typer.echo(
        f"Make keys for robots and dashboards with it, or with `{keys_create_hint(settings)}`."
    )


def keys_create_hint(settings: Settings, scope: str = "read") -> str:
    return f"fleetcal keys create --scope {scope} {data_dir_flag(settings)}".rstrip()


def data_dir_flag(settings: Settings) -> str:
    """`--data-dir DIR` for the hints this process prints: the directory it uses (nothing when
    `FLEETCAL_DATABASE_URL` names the database: the commands read it from there too)."""
    if settings.database_url is not None:
        return ""
    return f"--data-dir {shlex.quote(str(settings.data_dir))}"


def configure_logging(level: str) -> None:
    logging.basicConfig(
        level=level.upper(),
        format="%(asctime)s %(levelname)-7s %(name)s: %(message)s",
    )


@contextlib.contextmanager
def stop_signals(request_stop: Callable[..., None]) -> Iterator[None]:
    """While inside: SIGTERM and SIGINT call `request_stop()`, a second one
    `request_stop(now=True)`; the previous handlers come back on leaving."""
    received = [0]

    def handle(signum: int, frame: FrameType | None) -> None:
        received[0] += 1
        now = received[0] > 1
        logging.getLogger(__name__).warning(
            "%s: %s",
            signal.Signals(signum).name,
            "stopping now" if now else "stopping after the running runs",
        )
        request_stop(now=now)

    saved = {signum: signal.signal(signum, handle) for signum in (signal.SIGTERM, signal.SIGINT)}
    try:
        yield
    finally:
        for signum, handler in saved.items():
            signal.signal(signum, handler)
