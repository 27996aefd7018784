"""Stage 1, the noise filter, with the floor fit it stands on.

Stage 1 judges only the points standing above the floor (the object candidates, a tenth of a
full-rate cloud): bleeding points elsewhere never reach the later stages, and judging all would
cost ten times as much. Their neighbours are searched among every point. So each cloud's floor is
fitted first, here; its time is segmentation's (the floor is stage 2's). Clouds stay at full
rate: segmentation voxelises only what stands above the floor. Only non-repetitive LiDARs' clouds
are filtered (see `stage_1_filters`)."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from pipeline.config import PipelineConfig
from pipeline.denoise import DenoiseConfig, DenoiseResult, KeepMask, denoise
from pipeline.geometry import Plane
from pipeline.problem import LidarInfo, ScanPattern
from pipeline.segmentation import FloorFit, above_floor, fit_floor
from pipeline.stages.runner import Listeners, StageOutcome
from pipeline.stages.state import CalibrationState, Detail, PerCloud, per_cloud
from pipeline.transforms import Points


def stage_1_filters(lidar: LidarInfo, config: DenoiseConfig) -> bool:
    """Whether stage 1 filters this LiDAR's clouds: when enabled, for the scan patterns
    `config.filtered_patterns` names, by default non-repetitive scans only.

    The filter takes a point that is sparse for its place in the scan, on a sheet along its beam,
    for a mixed return (METHOD.md: a filter for non-repetitive scans). A spinning LiDAR re-fires
    the same directions every scan, so over a stop its points pile up along each beam, on scan
    lines degrees apart: its surfaces look like that too. Filtered, the spinning scenario's clouds
    lost 5,600 clean points above the floor for 3,600 mixed returns (seed 10) and calibrated
    6.0 mm off against 2.0 mm unfiltered (10 seeds); even removing exactly the labelled mixed
    returns gave 2.5 mm (bench_calibration's `labelled_stage1`), stage 2 already dropping the
    points whose surface the beam meets edge-on. A LiDAR whose pattern is UNKNOWN is not
    filtered either: filtering a spinning LiDAR cost 4 mm (above), leaving a Mid-70 unfiltered
    0.09 mm on average (the benchmark quoted at `PipelineConfig.denoise`).
    `config.scan_patterns` overrides the recording's pattern."""
    pattern = config.scan_patterns.get(lidar.frame, lidar.scan_pattern)
    return config.enabled and pattern in config.filtered_patterns


def denoise_above_floor(
    cloud: Points, floor: Plane, config: PipelineConfig, frame: str | None = None
) -> DenoiseResult:
    """Stage 1 as the pipeline runs it on one stop cloud (N, 3) in the LiDAR frame `frame`: only
    the points standing above `floor` (object candidates) are judged, against all their
    neighbours. The frame picks its optical axis (`denoise.optical_axes`)."""
    judge = above_floor(cloud, floor, config.segmentation)
    plane = np.array([*floor.normal, floor.offset], dtype=np.float64)  # a x + b y + c z + d = 0
    axis = config.denoise.optical_axes.get(frame or "", config.denoise.optical_axis)
    return denoise(cloud, config.denoise, axis, floor_plane=plane, judge=judge)


def fit_floors(state: CalibrationState, config: PipelineConfig) -> PerCloud[FloorFit | None]:
    """Each cloud's floor (RANSAC in the LiDAR frame around its expected up), None where none."""

    def fitted(at: tuple[int, int]) -> FloorFit | None:
        lidar, stop = at
        cloud = state.clouds_in_lidar[lidar][stop]
        return fit_floor(cloud, state.up_in_lidar[lidar], config.segmentation)

    return per_cloud(state.clouds_in_lidar, fitted)


@dataclasses.dataclass(frozen=True)
class _Filtered:
    kept: PerCloud[KeepMask | None]
    judged_points: int
    removed_points: int
    by_frame: dict[str, tuple[int, int]] = dataclasses.field(default_factory=dict)
    """Per filtered LiDAR frame: (points judged, points removed) over all stops."""


def _filter(
    state: CalibrationState,
    floors: PerCloud[FloorFit | None],
    frames: tuple[str, ...],
    config: PipelineConfig,
) -> _Filtered:
    """Stage 1 on the clouds of the LiDARs `frames` that have a floor; the rest all kept."""

    def filtered(at: tuple[int, int]) -> DenoiseResult | None:
        lidar, stop = at
        frame, floor = state.lidars[lidar].frame, floors[lidar][stop]
        if frame not in frames or floor is None:
            return None
        return denoise_above_floor(state.clouds_in_lidar[lidar][stop], floor[0], config, frame)

    results = per_cloud(state.clouds_in_lidar, filtered)
    kept: list[tuple[KeepMask | None, ...]] = []
    judged = removed = 0
    by_frame: dict[str, tuple[int, int]] = {}
    for lidar, row_results in zip(state.lidars, results, strict=True):
        row: list[KeepMask | None] = []
        for result in row_results:
            if result is None:
                row.append(None)
                continue
            judged += result.judged_points
            removed += result.removed_points
            frame_judged, frame_removed = by_frame.get(lidar.frame, (0, 0))
            by_frame[lidar.frame] = (
                frame_judged + result.judged_points,
                frame_removed + result.removed_points,
            )
            row.append(result.keep if result.removed_points else None)
        kept.append(tuple(row))
    return _Filtered(tuple(kept), judged, removed, by_frame)


def run(state: CalibrationState, config: PipelineConfig, listeners: Listeners) -> StageOutcome:
    """Fit the floors, then filter the clouds of the LiDARs stage 1 is for."""
    started = time.perf_counter()
    floors = fit_floors(state, config)
    floor_seconds = time.perf_counter() - started
    frames = tuple(lidar.frame for lidar in state.lidars if stage_1_filters(lidar, config.denoise))
    filtered = _filter(state, floors, frames, config)
    new_state = dataclasses.replace(
        state,
        floors_in_lidar=floors,
        kept=filtered.kept,
        filtered_frames=frames,
        floor_seconds=floor_seconds,
    )
    details: dict[str, Detail] = {
        "input_points": sum(len(cloud) for row in state.clouds_in_lidar for cloud in row),
        "judged_points": filtered.judged_points,
        "removed_points": filtered.removed_points,
        "enabled": config.denoise.enabled,
        "filtered_frames": ",".join(frames),
        "method": str(config.denoise.method),
    }
    for frame, (frame_judged, frame_removed) in filtered.by_frame.items():
        details[f"judged_points.{frame}"] = frame_judged
        details[f"removed_points.{frame}"] = frame_removed
    message = _message(new_state, filtered, config.denoise)
    return StageOutcome(new_state, details, message, credited_seconds=-floor_seconds)


def _message(state: CalibrationState, filtered: _Filtered, config: DenoiseConfig) -> str:
    if not config.enabled:
        return "disabled"
    unfiltered = [f for f in state.lidars if f.frame not in state.filtered_frames]
    reasons = {
        ScanPattern.UNKNOWN: "scan pattern unknown",
        ScanPattern.REPETITIVE: "repetitive scans",
        ScanPattern.NON_REPETITIVE: "non-repetitive scans, not in denoise.filtered_patterns",
    }
    by_reason: dict[str, list[str]] = {}
    for lidar in unfiltered:
        pattern = config.scan_patterns.get(lidar.frame, lidar.scan_pattern)
        by_reason.setdefault(reasons[pattern], []).append(lidar.frame)
    left_alone = "; ".join(
        f"{', '.join(frames)} not filtered ({reason})" for reason, frames in by_reason.items()
    )
    if not state.filtered_frames:
        return left_alone
    message = (
        f"removed {filtered.removed_points} of the {filtered.judged_points} points above the floor"
    )
    return f"{message}; {left_alone}" if unfiltered else message
