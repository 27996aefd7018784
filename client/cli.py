"""The client's commands of the `fleetcal` CLI: `upload`, `export` (client/export.py),
`profiles list|show|set`, `runs list|show`, all against the API at --url with the key of --key
or FLEETCAL_API_KEY."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import typer

from client.errors import ClientError
from service.enums import RunKind, RunStatus

UrlOption = Annotated[
    str, typer.Option("--url", envvar="FLEETCAL_URL", help="The fleetcal service.")
]
KeyOption = Annotated[
    str | None,
    typer.Option("--key", envvar="FLEETCAL_API_KEY", help="API key (else $FLEETCAL_API_KEY)."),
]
RetriesOption = Annotated[
    int, typer.Option("--retries", min=0, help="Retries on network errors and 502/503/504.")
]
DEFAULT_URL = "http://127.0.0.1:8000"

profiles_app = typer.Typer(help="Tolerance profiles: list, show, set.", no_args_is_help=True)
runs_app = typer.Typer(help="Runs: list (with filters), show.", no_args_is_help=True)


def register(app: typer.Typer) -> None:
    from client import export

    app.command("upload")(upload_command)
    export.register(app)
    app.add_typer(profiles_app, name="profiles")
    app.add_typer(runs_app, name="runs")


def _say(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


@contextmanager
def _exits() -> Iterator[None]:
    try:
        yield
    except ClientError as err:
        _say(f"error: {err}")
        raise typer.Exit(err.exit_code) from None


def _api(url: str, key: str | None, retries: int = 6, **kwargs: Any) -> Any:
    from client.api import Api

    return Api(url, key, retries=retries, on_retry=_say, **kwargs)


def upload_command(
    path: Annotated[Path, typer.Argument(help="bag directory, or a .mcap/.db3/.bag/.zip/.tar")],
    robot: Annotated[str, typer.Option("--robot", help="The robot's id.")],
    kind: Annotated[RunKind, typer.Option("--kind", help="Why the robot is calibrated.")],
    url: UrlOption = DEFAULT_URL,
    key: KeyOption = None,
    wait: Annotated[
        bool, typer.Option("--wait", help="Follow the run; exit 0 passed, 1 failed verdict.")
    ] = False,
    config: Annotated[
        Path | None, typer.Option("--config", help="YAML/JSON run config (X-Fleetcal-Config).")
    ] = None,
    retries: RetriesOption = 6,
    backoff: Annotated[float, typer.Option("--backoff", min=0, help="First retry delay, s.")] = 1.0,
    wait_timeout: Annotated[
        float, typer.Option("--wait-timeout", min=1, help="Seconds --wait waits for the end.")
    ] = 3600.0,
) -> None:
    """Upload a calibration recording. Exit 0 uploaded (with --wait: passed), 1 failed verdict,
    2 bad input or refused, 3 service unreachable after the retries. Running it again after a
    failure never makes a second run."""
    from client.payload import payload_for
    from client.progress import Progress
    from client.upload import load_config, outcome, upload, wait_for_run

    with _exits():
        payload = payload_for(path)
        run_config = load_config(config)
        bar = Progress(payload.size)
        api = _api(url, key, retries, backoff_s=backoff)
        api.on_retry = bar.line
        _say(f"uploading {path} ({payload.size} bytes, sha256 {payload.sha256[:12]}...)")
        sent = upload(api, payload, robot=robot, kind=kind.value, config=run_config, progress=bar)
        run_id = sent.run["id"]
        _say(f"run {run_id} {'(already uploaded) ' if sent.replayed else ''}{sent.run['status']}")
        typer.echo(run_id)
        if not wait:
            return
        api.on_retry = _say
        code, lines = outcome(wait_for_run(api, run_id, say=_say, timeout_s=wait_timeout))
        for line in lines:
            typer.echo(line)
        raise typer.Exit(code)


# -- profiles -------------------------------------------------------------------------------------


def _print(data: Any) -> None:
    typer.echo(json.dumps(data, indent=2))


def _read(call: Callable[[], Any]) -> None:
    with _exits():
        _print(call())


@profiles_app.command("list")
def profiles_list(url: UrlOption = DEFAULT_URL, key: KeyOption = None) -> None:
    """Every tolerance profile (JSON)."""
    _read(lambda: _api(url, key).json("GET", "/v1/tolerance-profiles"))


@profiles_app.command("show")
def profiles_show(name: str, url: UrlOption = DEFAULT_URL, key: KeyOption = None) -> None:
    """One tolerance profile (JSON)."""
    _read(lambda: _api(url, key).json("GET", f"/v1/tolerance-profiles/{name}"))


@profiles_app.command("set")
def profiles_set(
    name: str,
    file: Annotated[Path, typer.Argument(help="YAML: robot_model, is_default, limits, ...")],
    url: UrlOption = DEFAULT_URL,
    key: KeyOption = None,
) -> None:
    """Create or replace a profile from a YAML file (admin key)."""
    from client.upload import load_config

    def put() -> Any:
        body = load_config(file)
        return _api(url, key).json(
            "PUT", f"/v1/tolerance-profiles/{name}", ok=(200, 201), json=body
        )

    _read(put)


# -- runs -----------------------------------------------------------------------------------------


@runs_app.command("list")
def runs_list(
    url: UrlOption = DEFAULT_URL,
    key: KeyOption = None,
    robot: Annotated[str | None, typer.Option("--robot")] = None,
    status: Annotated[RunStatus | None, typer.Option("--status")] = None,
    kind: Annotated[RunKind | None, typer.Option("--kind")] = None,
    passed: Annotated[bool | None, typer.Option("--passed/--failed", show_default=False)] = None,
    since: Annotated[str | None, typer.Option("--since", help="ISO 8601 instant.")] = None,
    until: Annotated[str | None, typer.Option("--until", help="ISO 8601 instant.")] = None,
    limit: Annotated[int, typer.Option("--limit", min=1)] = 50,
    cursor: Annotated[str | None, typer.Option("--cursor", help="next_cursor of a page.")] = None,
) -> None:
    """Runs, newest first: one page as JSON (`next_cursor` fetches the next)."""
    filters = {
        "robot_id": robot,
        "status": status.value if status else None,
        "kind": kind.value if kind else None,
        "passed": None if passed is None else str(passed).lower(),
        "since": since,
        "until": until,
        "limit": limit,
        "cursor": cursor,
    }
    params = {name: value for name, value in filters.items() if value is not None}
    _read(lambda: _api(url, key).json("GET", "/v1/runs", params=params))


@runs_app.command("show")
def runs_show(run_id: str, url: UrlOption = DEFAULT_URL, key: KeyOption = None) -> None:
    """One run: status, progress, result or error (JSON)."""
    _read(lambda: _api(url, key).json("GET", f"/v1/runs/{run_id}"))
