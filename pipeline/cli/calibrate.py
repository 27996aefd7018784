"""`fleetcal calibrate PATH --output result.json`: a recording in, `result.json` and a summary out.

Exit codes: 0 the verdict passed, 1 it ran and the verdict failed, 2 bad input (no traceback).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from pipeline.cli.common import (
    EXIT_FAILED_VERDICT,
    EXIT_OK,
    RecordingPath,
    check_writable,
    progress,
    user_errors,
)

if TYPE_CHECKING:
    from pipeline.calibrate import CalibrationResult
    from pipeline.config import PipelineConfig


def register(app: typer.Typer) -> None:
    app.command("calibrate")(calibrate_command)


def calibrate_command(
    path: RecordingPath,
    output: Annotated[Path, typer.Option("--output", "-o", help="where to write result.json")],
    config_path: Annotated[
        Path | None,
        typer.Option("--config", help="YAML file of pipeline parameters (any subset, by stage)"),
    ] = None,
    reference: Annotated[
        str | None,
        typer.Option(help="reference LiDAR frame [default: the first LiDAR frame, sorted]"),
    ] = None,
) -> None:
    """Calibrate every LiDAR of a recording relative to the reference LiDAR."""
    from pipeline.calibrate import calibrate
    from pipeline.io import read_recording
    from pipeline.result import dumps

    with user_errors():
        check_writable(output)
        config = _config(config_path, reference)
        started = time.perf_counter()
        problem = read_recording(path, config.reader)
        read_seconds = time.perf_counter() - started
        progress(
            f"read: {len(problem.lidars)} LiDARs, {len(problem.stops)} stops, "
            f"{problem.kept_points()} points ({read_seconds:.2f} s)"
        )
        result = calibrate(
            problem,
            config,
            progress=lambda stage, seconds, message: progress(
                f"{stage}: {message} ({seconds:.2f} s)"
            ),
        )
        text = dumps(result, read_seconds=read_seconds)
        try:
            output.write_text(text, encoding="utf-8")
        except OSError as err:
            from pipeline.errors import BadInputError

            raise BadInputError(
                f"cannot write {output}: {err.strerror or err}; choose a writable path"
            ) from None
    for warning in result.warnings:
        progress(f"warning: {warning}")
    typer.echo(summary(result))
    raise typer.Exit(EXIT_OK if result.passed else EXIT_FAILED_VERDICT)


def _config(path: Path | None, reference: str | None) -> PipelineConfig:
    from pipeline.config import PipelineConfig, config_from_mapping, load_config, resolved

    config = load_config(path) if path is not None else PipelineConfig()
    if reference is None:
        return config
    data = resolved(config)
    data["frames"]["reference_frame"] = reference
    return config_from_mapping(data)


def summary(result: CalibrationResult) -> str:
    """The per-LiDAR table, the metric error before and after, and the verdict."""
    from scipy.spatial.transform import Rotation

    def pose(T: object) -> str:
        import numpy as np

        matrix = np.asarray(T)
        rpy = np.degrees(Rotation.from_matrix(matrix[:3, :3]).as_euler("xyz"))
        xyz = matrix[:3, 3]
        return "{:+.4f} {:+.4f} {:+.4f} | {:+7.2f} {:+7.2f} {:+7.2f}".format(*xyz, *rpy)

    header = (
        f"{'LiDAR':<17} {'':<10} {'x, y, z (m) | roll, pitch, yaw (deg)':<50} "
        f"{'change (mm, deg)':>18}  {'1-sigma (mm / deg)':>18}"
    )
    lines = [header, "-" * len(header)]
    for lidar in result.lidars:
        name = lidar.frame + (" (ref)" if lidar.is_reference else "")
        translation, rotation = lidar.change
        sigma_t = 1000 * float(max(lidar.uncertainty.stddev_translation_m))
        sigma_r = float(max(lidar.uncertainty.stddev_rotation_deg))
        lines.append(f"{name:<17} {'initial':<10} {pose(lidar.T_base_lidar_initial)}")
        if lidar.uncertainty.undetermined:
            lines.append(
                f"{'':<17} {'calibrated':<10} undetermined: "
                f"{', '.join(lidar.uncertainty.undetermined)}"
            )
            continue
        lines.append(
            f"{'':<17} {'calibrated':<10} {pose(lidar.T_base_lidar_calibrated)} "
            f"{translation * 1000:9.1f} {rotation:8.2f}  {sigma_t:10.2f} / {sigma_r:6.3f}"
        )
    lines.append("")
    lines.append(
        f"metric error (eq. 12): {_metres(result.metric_error_initial)} -> "
        f"{_metres(result.metric_error_final)}"
    )
    seen = [lidar for lidar in result.lidars if not lidar.is_reference]
    lines.append(
        "off the surfaces the reference saw (seen metric): "
        + ", ".join(f"{lidar.frame} {_metres(lidar.seen_metric_final)}" for lidar in seen)
    )
    if result.verdict.passed:
        lines.append(f"verdict: PASSED ({len(result.verdict.checks)} checks)")
    else:
        lines.append("verdict: FAILED")
        for check in result.verdict.failed:
            lines.append(f"  {check.name}: {check.detail or f'{check.value} vs {check.limit}'}")
    return "\n".join(lines)


def _metres(value: float) -> str:
    return "n/a" if value != value else f"{value * 1000:.2f} mm"
