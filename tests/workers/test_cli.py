"""`fleetcal` start-up: help and inspect load only what they use (issue 17's start-up cut).

Each case runs the CLI in a fresh interpreter, as a user's shell does, and lists the heavy
packages it left in `sys.modules`.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

from pipeline.io.writer import WriterFormat
from tests.pipeline.io.recordings import Spec, write_recording

# Packages that cost a second or more together and that neither help nor inspect needs.
NEVER_FOR_HELP_OR_INSPECT = (
    "open3d",
    "matplotlib",
    "mujoco",
    "fastapi",
    "starlette",
    "sqlalchemy",
    "alembic",
    "uvicorn",
    "httpx",
    "boto3",
    "pydantic_settings",
    "service.app",
    "service.db",
)

# The numerical and service stacks, and typer's rich help: none is needed to list the commands.
NEVER_TO_BUILD_THE_CLI = (
    "numpy",
    "scipy",
    "open3d",
    "mujoco",
    "matplotlib",
    "pydantic",
    "sqlalchemy",
    "fastapi",
    "rich",
)

# Runs `fleetcal ARGS` in-process, then prints which of the watched modules got imported.
_PROBE = """
import json, sys
from workers.cli import main
watched = json.loads(sys.argv[1])
sys.argv = ["fleetcal", *sys.argv[2:]]
try:
    main()
except SystemExit as exit:
    code = exit.code
else:
    code = 0
loaded = sorted(m for m in watched if m in sys.modules)
print("\\nLOADED " + json.dumps({"code": code, "loaded": loaded}))
"""


# Imports the CLI and builds every command's click object (typer does it on the first call),
# then prints which of the watched modules got imported.
_BUILD_PROBE = """
import json, sys
import typer.main
from workers.cli import app
typer.main.get_command(app)
watched = json.loads(sys.argv[1])
loaded = sorted(m for m in watched if m in sys.modules)
print("\\nLOADED " + json.dumps({"code": 0, "loaded": loaded}))
"""

# Runs `fleetcal CMD --help` in-process for every command and sub-command of the built app.
_EVERY_HELP_PROBE = """
import json, sys
import typer.main
from workers.cli import app

def paths(command, path):
    yield path
    for name, sub in sorted(getattr(command, "commands", {}).items()):
        yield from paths(sub, [*path, name])

root = typer.main.get_command(app)
shown = []
for path in paths(root, []):
    try:
        root.main([*path, "--help"], prog_name="fleetcal", standalone_mode=False)
    except SystemExit as exit:
        if exit.code not in (0, None):
            raise
    shown.append(" ".join(path))
watched = json.loads(sys.argv[1])
loaded = sorted(m for m in watched if m in sys.modules)
print("\\nLOADED " + json.dumps({"code": 0, "loaded": loaded, "shown": shown}))
"""


def imported_by(*args: str, watched: tuple[str, ...]) -> list[str]:
    """The modules of `watched` that `fleetcal ARGS` imported; fails if the command failed."""
    return list(_probe(_PROBE, *args, watched=watched)["loaded"])


def _probe(source: str, *args: str, watched: tuple[str, ...]) -> dict[str, Any]:
    """Run `source` in a fresh interpreter and return the report it printed last."""
    repo = Path(__file__).resolve().parents[2]
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(repo), os.environ.get("PYTHONPATH", "")]),
    }
    done = subprocess.run(
        [sys.executable, "-c", source, json.dumps(watched), *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        check=False,
    )
    last = done.stdout.rstrip().rsplit("\nLOADED ", 1)
    assert len(last) == 2, f"probe printed no result:\n{done.stdout}\n{done.stderr}"
    report: dict[str, Any] = json.loads(last[1])
    assert report["code"] in (0, None), f"fleetcal {' '.join(args)} failed:\n{done.stderr}"
    return report


def test_building_the_cli_imports_no_numerical_nor_service_stack() -> None:
    # What `fleetcal --help` costs is what this import graph holds: typer and the command
    # modules' own top levels (option defaults are literals, heavy imports are in the bodies).
    assert _probe(_BUILD_PROBE, watched=NEVER_TO_BUILD_THE_CLI)["loaded"] == []


def test_root_help_imports_no_numerical_nor_service_stack() -> None:
    assert imported_by("--help", watched=NEVER_TO_BUILD_THE_CLI) == []


def test_every_commands_help_imports_no_numerical_stack() -> None:
    # pydantic is not watched: typer itself coerces a sub-command's parameters with it.
    watched = tuple(m for m in NEVER_TO_BUILD_THE_CLI if m != "pydantic")
    report = _probe(_EVERY_HELP_PROBE, watched=(*watched, *NEVER_FOR_HELP_OR_INSPECT))

    assert report["loaded"] == []
    assert {"calibrate", "denoise", "export", "inspect", "keys create", "runs list"} <= set(
        report["shown"]
    )


def test_inspect_loads_no_renderer_simulator_nor_service(tmp_path: Path) -> None:
    recording = tmp_path / "rec.bag"
    write_recording(recording, WriterFormat.ROS1, Spec(stops=2, points=60))

    assert imported_by("inspect", str(recording), "--json", watched=NEVER_FOR_HELP_OR_INSPECT) == []


def test_probe_sees_an_imported_module() -> None:
    # Guards the probe itself: `fleetcal openapi` builds the app, so it must report fastapi.
    assert imported_by("openapi", watched=("fastapi",)) == ["fastapi"]
