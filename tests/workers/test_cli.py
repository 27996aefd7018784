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

import pytest

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


def imported_by(*args: str, watched: tuple[str, ...]) -> list[str]:
    """The modules of `watched` that `fleetcal ARGS` imported; fails if the command failed."""
    repo = Path(__file__).resolve().parents[2]
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(repo), os.environ.get("PYTHONPATH", "")]),
    }
    done = subprocess.run(
        [sys.executable, "-c", _PROBE, json.dumps(watched), *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        check=False,
    )
    last = done.stdout.rstrip().rsplit("\nLOADED ", 1)
    assert len(last) == 2, f"probe printed no result:\n{done.stdout}\n{done.stderr}"
    report = json.loads(last[1])
    assert report["code"] in (0, None), f"fleetcal {' '.join(args)} failed:\n{done.stderr}"
    return list(report["loaded"])


@pytest.mark.parametrize("args", [("--help",), ("inspect", "--help"), ("calibrate", "--help")])
def test_help_loads_no_scipy_nor_heavy_stack(args: tuple[str, ...]) -> None:
    assert imported_by(*args, watched=(*NEVER_FOR_HELP_OR_INSPECT, "scipy")) == []


def test_inspect_loads_no_renderer_simulator_nor_service(tmp_path: Path) -> None:
    recording = tmp_path / "rec.bag"
    write_recording(recording, WriterFormat.ROS1, Spec(stops=2, points=60))

    assert imported_by("inspect", str(recording), "--json", watched=NEVER_FOR_HELP_OR_INSPECT) == []


def test_probe_sees_an_imported_module() -> None:
    # Guards the probe itself: `fleetcal openapi` builds the app, so it must report fastapi.
    assert imported_by("openapi", watched=("fastapi",)) == ["fastapi"]
