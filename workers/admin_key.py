"""The first admin key's one showing, and the command that makes more keys, as the processes that
create it (`fleetcal serve`, `fleetcal demo`) print them."""

from __future__ import annotations

import shlex
from typing import TYPE_CHECKING

import typer

if TYPE_CHECKING:
    from service.settings import Settings


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
