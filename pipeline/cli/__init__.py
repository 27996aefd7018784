"""The pipeline's commands of the `fleetcal` CLI (inspect, synth, denoise, calibrate, ...);
`fleetcal export` is the client's (client/export.py), since it also fetches runs over HTTP.

Each command lives in its own module with a `register(app)` function; heavy modules (open3d,
mujoco, rosbags) are imported inside the command so that `fleetcal --help` stays instant.
"""

from __future__ import annotations

import importlib

import typer

_COMMAND_MODULES: tuple[str, ...] = (
    "inspect",
    "denoise",
    "synth",
    "export_map",
    "calibrate",
)


def register(app: typer.Typer) -> None:
    """Add every pipeline command to `app`."""
    for name in _COMMAND_MODULES:
        importlib.import_module(f"pipeline.cli.{name}").register(app)
