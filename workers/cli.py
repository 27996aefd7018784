"""The `fleetcal` command line.

The root lives in `workers` because it is the one package allowed to depend on both `pipeline`
and `service` (DESIGN.md's dependency direction); each package registers its own commands.
"""

from __future__ import annotations

import typer

from client import cli as client_cli
from pipeline import cli as pipeline_cli
from service import cli as service_cli
from workers import commands as worker_commands

app = typer.Typer(
    name="fleetcal",
    help="Extrinsic calibration of multiple LiDARs on ground robots, for whole fleets.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # Plain click help and errors: typer's rich help imports rich and markdown-it, over half
    # of what `fleetcal --help` cost (issue 17: under 0.5 s).
    rich_markup_mode=None,
)
pipeline_cli.register(app)
service_cli.register(app)
worker_commands.register(app)
client_cli.register(app)


@app.command()
def version() -> None:
    """Print the pipeline version."""
    from pipeline import __version__

    typer.echo(__version__)


def main() -> None:
    app()
