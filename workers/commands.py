"""The workers' commands of the `fleetcal` CLI: `worker` (distributed), `serve` (embedded API and
workers), `demo` (the main job end to end on a fresh machine). Heavy imports stay in the bodies."""

from __future__ import annotations

import os
import threading
from datetime import timedelta
from typing import Annotated

import typer

from service.cli import DataDirOption, settings_for, startup_errors

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
    from workers.demo import demo

    app.command("worker")(worker)
    app.command("serve")(serve)
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
    from workers.process import configure_logging, stop_signals
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
    from workers.admin_key import print_first_admin_key
    from workers.embedded import EmbeddedService, first_admin_key
    from workers.process import configure_logging, stop_signals
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
