"""`fleetcal inspect PATH [--json]`: what a user checks in a recording before uploading it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer

from pipeline.cli.common import RecordingPath, user_errors


def register(app: typer.Typer) -> None:
    app.command("inspect")(inspect_command)


def inspect_command(
    path: RecordingPath,
    as_json: Annotated[bool, typer.Option("--json", help="print one JSON document")] = False,
    config_path: Annotated[
        Path | None,
        typer.Option("--config", help="YAML reader config (topics, frames, extrinsics, stops)"),
    ] = None,
    odometry_topic: Annotated[
        str | None, typer.Option(help="nav_msgs/Odometry topic [default: /odom]")
    ] = None,
    base_frame: Annotated[
        str | None, typer.Option(help="robot body frame [default: base_link]")
    ] = None,
) -> None:
    """Format, duration, LiDARs and point rates, stops, initial extrinsics, and warnings."""
    from pipeline.io.inspection import inspect_recording

    with user_errors():
        config = _config(config_path, odometry_topic=odometry_topic, base_frame=base_frame)
        document = inspect_recording(path, config)
    if as_json:
        typer.echo(json.dumps(document, indent=2))
    else:
        typer.echo(render(document))


def _config(path: Path | None, **overrides: str | None) -> Any:
    """The reader config from `--config` (top level, or its `reader` section) and the options."""
    import yaml
    from pydantic import ValidationError

    from pipeline.errors import ConfigError
    from pipeline.io.config import ReaderConfig

    data: dict[str, Any] = {}
    if path is not None:
        try:
            loaded = yaml.safe_load(path.read_text()) or {}
        except (OSError, yaml.YAMLError) as err:
            raise ConfigError(f"cannot read the config {path}: {err}; pass a YAML file") from None
        if not isinstance(loaded, dict):
            raise ConfigError(f"{path} must hold a mapping of reader settings")
        data = dict(loaded.get("reader", loaded))
    data.update({key: value for key, value in overrides.items() if value is not None})
    try:
        return ReaderConfig.model_validate(data)
    except ValidationError as err:
        problems = "; ".join(
            f"{'.'.join(map(str, e['loc'])) or 'config'}: {e['msg']}" for e in err.errors()
        )
        raise ConfigError(f"invalid reader config: {problems}") from None


def render(document: dict[str, Any]) -> str:
    """The inspection document as an aligned text report."""
    lines = [
        f"recording   {document['path']}",
        f"format      {document['format']} ({document['storage']} storage)",
        f"duration    {document['duration']:.1f} s, {document['messages']} messages",
        f"trajectory  {document['trajectory']} ({document['odom_frame']} -> "
        f"{document['base_frame']})",
        f"LiDARs      {len(document['lidars'])}",
    ]
    width = max(len(lidar["frame"]) for lidar in document["lidars"])
    for lidar in document["lidars"]:
        initial = lidar["initial"]
        pose = (
            "no initial extrinsics"
            if initial is None
            else "T_base_lidar t=[{}] m q=[{}] ({})".format(
                ", ".join(f"{v:.3f}" for v in initial["translation"]),
                ", ".join(f"{v:.3f}" for v in initial["rotation_xyzw"]),
                lidar["initial_source"],
            )
        )
        lines.append(
            f"  {lidar['frame']:<{width}}  {lidar['topic']}  {lidar['scans']} scans, "
            f"{lidar['points_per_second'] / 1000:.1f} k points/s, "
            f"{lidar['scan_pattern'].replace('_', '-')} scans; {pose}"
        )
    lines += _clock_lines(document)
    lines += _stop_lines(document)
    lines.append(f"warnings    {len(document['warnings']) or 'none'}")
    lines += [f"  - {warning}" for warning in document["warnings"]]
    return "\n".join(lines)


def _lag(offset_s: float) -> str:
    return f"{abs(offset_s):.3f} s {'behind' if offset_s >= 0 else 'ahead of'} the log time"


def _clock_lines(document: dict[str, Any]) -> list[str]:
    """The trajectory's header clock, and each LiDAR whose clock disagrees with it."""
    shifted = [lidar for lidar in document["lidars"] if lidar["clock_shift"]]
    lines = [
        f"clocks      trajectory header stamps {_lag(document['trajectory_header_offset'])}; "
        + (f"{len(shifted)} LiDAR(s) on another clock" if shifted else "LiDARs on the same clock")
    ]
    lines += [
        f"  {lidar['frame']}  header stamps {_lag(lidar['header_offset'])}: "
        f"shifted by {lidar['clock_shift']:+.3f} s onto the trajectory's clock"
        for lidar in shifted
    ]
    return lines


def _stop_lines(document: dict[str, Any]) -> list[str]:
    """One row per stop: its span, its duration, and the scans each LiDAR has wholly inside."""
    stops, frames = document["stops"], [lidar["frame"] for lidar in document["lidars"]]
    mean = sum(stop["duration"] for stop in stops) / len(stops)
    widths = [max(len(frame), 5) for frame in frames]
    lines = [
        f"stops       {len(stops)} (mean {mean:.2f} s; times from the recording's start; "
        "scans wholly inside each, per LiDAR)",
        "                 span            duration  "
        + "  ".join(f"{frame:>{w}}" for frame, w in zip(frames, widths, strict=True)),
    ]
    t0 = document["start"]
    for k, stop in enumerate(stops):
        scans = "  ".join(
            f"{stop['scans'][frame]:>{w}}" for frame, w in zip(frames, widths, strict=True)
        )
        lines.append(
            f"  {k:>3}  {stop['start'] - t0:7.2f} - {stop['end'] - t0:7.2f} s"
            f"  {stop['duration']:6.2f} s  {scans}"
        )
    return lines
