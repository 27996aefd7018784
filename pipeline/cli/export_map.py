"""`fleetcal export-map RESULT --recording REC --format ply|pcd --out DIR`: the accumulated map
before and after calibration (`map_before.*`, `map_after.*`), one colour per LiDAR."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from pipeline.cli.common import progress, user_errors
from pipeline.export import MapFormat


def register(app: typer.Typer) -> None:
    app.command("export-map")(export_map_command)


def export_map_command(
    result: Annotated[Path, typer.Argument(help="result.json (or a saved run document)")],
    recording: Annotated[
        Path, typer.Option("--recording", help="the recording the result was calibrated from")
    ],
    out: Annotated[Path, typer.Option("--out", "-o", help="folder for map_before/map_after")],
    fmt: Annotated[MapFormat, typer.Option("--format", "-f", help="ply or pcd")] = MapFormat.PLY,
    allow_failed: Annotated[
        bool, typer.Option("--allow-failed", help="export a result whose verdict failed")
    ] = False,
    max_points: Annotated[int, typer.Option("--max-points", min=1)] = 2_000_000,
) -> None:
    """Write the map before and after calibration as PLY or PCD, for CloudCompare, RViz or
    Foxglove."""
    from pipeline.cli.export import load_result
    from pipeline.config import PipelineConfig
    from pipeline.io import read_recording
    from pipeline.map_export import maps_before_after, write_map

    with user_errors():
        document, _ = load_result(result)
        config = PipelineConfig.model_validate(document.get("config") or {})
        problem = read_recording(recording, config.reader)
        before, after = maps_before_after(
            problem, document, allow_failed=allow_failed, max_points=max_points
        )
        out.mkdir(parents=True, exist_ok=True)
        for name, cloud in (("map_before", before), ("map_after", after)):
            written = write_map(out / f"{name}.{fmt.value}", cloud, fmt)
            progress(
                f"wrote {written} ({cloud.points.shape[0]} points, {len(cloud.frames)} LiDARs)"
            )
