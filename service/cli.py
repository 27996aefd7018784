"""The service's commands of the `fleetcal` CLI: `keys create|list|revoke`, `db upgrade|current`,
`openapi`. Every command that touches state takes `--data-dir` (else `FLEETCAL_*` settings)."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from service.enums import Scope

if TYPE_CHECKING:
    from service.db import Database
    from service.settings import Settings

DataDirOption = Annotated[
    Path | None,
    typer.Option(
        "--data-dir",
        help="Directory of the embedded database and storage [default: $FLEETCAL_DATA_DIR or "
        "./.fleetcal].",
        file_okay=False,
    ),
]

keys_app = typer.Typer(help="Create, list and revoke API keys.", no_args_is_help=True)
db_app = typer.Typer(help="Database migrations.", no_args_is_help=True)


def register(app: typer.Typer) -> None:
    """Add the service's commands to the root `fleetcal` app."""
    app.add_typer(keys_app, name="keys")
    app.add_typer(db_app, name="db")
    app.command("openapi")(openapi)


EXIT_BAD_SETUP = 2


@contextmanager
def startup_errors() -> Iterator[None]:
    """Run a command body; a `StartupError` (bad settings, an unreachable database or storage, a
    busy port) becomes `error: <message>` on stderr and exit code 2, without a traceback."""
    from service.startup import StartupError

    try:
        yield
    except StartupError as err:
        typer.echo(f"error: {err}", err=True)
        raise typer.Exit(EXIT_BAD_SETUP) from None


def settings_for(data_dir: Path | None) -> Settings:
    """The settings of a command: `--data-dir` over `FLEETCAL_*`; exit 2 if they are invalid."""
    from service.startup import load_settings

    with startup_errors():
        return load_settings(data_dir)


def _database(data_dir: Path | None, *, create: bool) -> Database:
    """The database the settings name, migrated, after saying on stderr which one it is. A SQLite
    file that does not exist yet is created only if `create`: listing or revoking keys in a fresh
    directory means the command was pointed at the wrong one."""
    from service.startup import StartupError, open_database, sqlite_file, where_state_lives

    settings = settings_for(data_dir)
    with startup_errors():
        file = sqlite_file(settings)
        new = file is not None and not file.exists()
        if new and not create:
            raise StartupError(
                f"no database in {where_state_lives(settings)}: no service has used it yet; pass "
                "--data-dir DIR (or set FLEETCAL_DATA_DIR) to the directory `fleetcal serve` uses"
            )
        db = open_database(settings, migrate=True)
    typer.echo(
        f"using the {where_state_lives(settings)}" + (" (new: created now)" if new else ""),
        err=True,
    )
    return db


@keys_app.command("create")
def keys_create(
    scope: Annotated[
        list[Scope],
        typer.Option("--scope", help="upload, read or admin; repeat for several.", min=1),
    ],
    robot: Annotated[
        str | None,
        typer.Option(
            "--robot",
            help="Bind an upload key to this robot id: it may upload for that robot only.",
        ),
    ] = None,
    name: Annotated[
        str | None, typer.Option("--name", help="A label to recognise the key.")
    ] = None,
    data_dir: DataDirOption = None,
) -> None:
    """Create a key and print it once: it is stored only as a hash and cannot be shown again."""
    import re

    from service.auth import create_key
    from service.schemas import ROBOT_ID_PATTERN

    if robot is not None and not re.fullmatch(ROBOT_ID_PATTERN, robot):
        raise typer.BadParameter(
            f"{robot!r} is not a robot id ({ROBOT_ID_PATTERN})", param_hint="--robot"
        )
    if robot is not None and set(scope) != {Scope.UPLOAD}:
        raise typer.BadParameter(
            "only --scope upload keys can be bound to a robot", param_hint="--robot"
        )
    db = _database(data_dir, create=True)
    try:
        with db.transaction() as session:
            key = create_key(session, list(scope), robot_id=robot, name=name)
    finally:
        db.dispose()
    bound = f" for robot {robot}" if robot else ""
    typer.echo(
        f"created key {key.id} ({', '.join(s.value for s in key.scopes)}{bound}); "
        "store it now, it will not be shown again:",
        err=True,
    )
    typer.echo(key.secret)


@keys_app.command("list")
def keys_list(data_dir: DataDirOption = None) -> None:
    """List keys (ids, scopes, robot, state); never the secrets."""
    from service.auth import list_keys

    db = _database(data_dir, create=False)
    try:
        with db.session() as session:
            rows = list_keys(session)
    finally:
        db.dispose()
    typer.echo(f"{'id':<14}{'scopes':<20}{'robot':<16}{'created (UTC)':<22}{'state':<10}name")
    for row in rows:
        state = "revoked" if row.revoked_at else "active"
        typer.echo(
            f"{row.id:<14}{','.join(row.scopes):<20}{row.robot_id or '-':<16}"
            f"{row.created_at:%Y-%m-%d %H:%M:%S}   {state:<10}{row.name or ''}"
        )


@keys_app.command("revoke")
def keys_revoke(
    key_id: Annotated[str, typer.Argument(help="The key's id (from `keys list`).")],
    data_dir: DataDirOption = None,
) -> None:
    """Revoke a key: requests with it get 401 from now on."""
    from service.auth import revoke_key

    db = _database(data_dir, create=False)
    try:
        with db.transaction() as session:
            found = revoke_key(session, key_id)
    finally:
        db.dispose()
    if not found:
        typer.echo(f"no key {key_id!r}; see `fleetcal keys list`", err=True)
        raise typer.Exit(1)
    typer.echo(f"revoked key {key_id}")


@db_app.command("upgrade")
def db_upgrade(
    revision: Annotated[str, typer.Argument(help="Target revision.")] = "head",
    data_dir: DataDirOption = None,
) -> None:
    """Apply the migrations up to REVISION (default: the newest)."""
    from service.startup import open_database, shown_database

    settings = settings_for(data_dir)
    with startup_errors():
        db = open_database(settings, migrate=None)
    try:
        db.upgrade(revision)
        current = ", ".join(sorted(db.current_revisions())) or "empty"
    finally:
        db.dispose()
    typer.echo(f"database {shown_database(settings)} at revision {current}")


@db_app.command("current")
def db_current(data_dir: DataDirOption = None) -> None:
    """Print the database's revision and whether it is the newest."""
    from service.startup import open_database

    settings = settings_for(data_dir)
    with startup_errors():
        db = open_database(settings, migrate=None)
    try:
        current, head = db.current_revisions(), db.head_revisions()
    finally:
        db.dispose()
    state = "up to date" if current == head else f"behind (newest: {', '.join(sorted(head))})"
    typer.echo(f"{', '.join(sorted(current)) or 'empty'}: {state}")
    if current != head:
        raise typer.Exit(1)


def openapi(
    output: Annotated[
        Path | None,
        typer.Option("--output", "-o", help="Write here instead of stdout.", dir_okay=False),
    ] = None,
    check: Annotated[
        bool, typer.Option("--check", help="Exit 1 if --output differs from the app's document.")
    ] = False,
) -> None:
    """Print (or write) the API's OpenAPI document, generated from the app."""
    from service.openapi import render_openapi

    text = render_openapi()
    if output is None:
        sys.stdout.write(text)
        return
    if check:
        if not output.is_file() or output.read_text() != text:
            typer.echo(
                f"{output} is out of date; run `fleetcal openapi --output {output}`", err=True
            )
            raise typer.Exit(1)
        return
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(text)
    typer.echo(f"wrote {output}", err=True)
