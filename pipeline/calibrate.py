"""`calibrate(problem, config)`: the four stages in order, then metric, observability and verdict.

Frames: G is the reference LiDAR's frame at stop 0 (`T_G_ref[0]` = identity, the gauge); the
unknowns are the reference's pose per stop `T_G_ref` and the extrinsics relative to it
`T_ref_lidar`; reported extrinsics are `T_base_lidar = T_base_ref @ T_ref_lidar`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import partial

import numpy as np
from numpy.typing import NDArray

from pipeline.config import FramesConfig, PipelineConfig, config_hash, unknown_frame_warnings
from pipeline.denoise import DenoiseConfig, DenoiseResult, KeepMask, denoise
from pipeline.errors import BadInputError
from pipeline.metric import metric_error
from pipeline.observability import PoseUncertainty, level_rotation, pose_uncertainties
from pipeline.optimisation import OptimisationResult, optimise
from pipeline.problem import CalibrationProblem, LidarInfo, ScanPattern
from pipeline.rough_refinement import RoughRefinementResult, refine_with_floor
from pipeline.segmentation import (
    FloorFit,
    Plane,
    Segmentation,
    above_floor,
    fit_floor,
    segment_on_floor,
)
from pipeline.transforms import Matrix4, Points, invert, make_transform, pose_difference
from pipeline.verdict import LidarEvidence, Verdict, judge

Progress = Callable[[str, float, str], None]
"""`progress(stage, seconds, message)`: called once per finished stage."""
IterationProgress = Callable[[int, int], None]
"""`on_iteration(iteration, max_iterations)`: called after each iteration of the optimisation."""

STAGES: tuple[str, ...] = (
    "denoise",
    "segmentation",
    "rough_refinement",
    "optimisation",
    "metric",
    "observability",
    "verdict",
)


def _iteration_of(on_iteration: IterationProgress, max_iterations: int, iteration: int) -> None:
    on_iteration(iteration, max_iterations)


@dataclass(frozen=True)
class StageReport:
    """Wall time of a stage and what it did (plain numbers and flags, for `result.json`)."""

    seconds: float
    details: Mapping[str, float | int | bool | str] = field(default_factory=dict)


@dataclass(frozen=True)
class LidarCalibration:
    """One LiDAR's outcome. Transforms (4, 4) `T_base_lidar`; `metric_*` is eq. 12 over this
    LiDAR's points alone (NaN for the reference)."""

    frame: str
    topic: str
    is_reference: bool
    T_base_lidar_initial: Matrix4
    T_base_lidar_calibrated: Matrix4
    uncertainty: PoseUncertainty
    object_points: int
    metric_initial: float
    metric_final: float

    @property
    def change(self) -> tuple[float, float]:
        """Translation (m) and rotation (deg) from the initial to the calibrated extrinsics."""
        return pose_difference(self.T_base_lidar_initial, self.T_base_lidar_calibrated)


@dataclass(frozen=True)
class CalibrationResult:
    """Everything `result.json` reports, plus the stage results for benchmarks.

    `lidars` has the reference first, then the others in sorted order. `T_odom_base` (J, 4, 4):
    the refined stop poses of the base in the odometry frame. `error_per_iteration`: eq. 11 of
    stage 4 per iteration (metres). `warnings`: what the user should fix or know, the recording's
    (`recording.warnings`) and the config's settings that name LiDAR frames it does not have.
    """

    reference_frame: str
    base_frame: str
    lidars: tuple[LidarCalibration, ...]
    metric_error_initial: float
    metric_error_final: float
    verdict: Verdict
    stages: Mapping[str, StageReport]
    converged: bool
    iterations: int
    error_per_iteration: tuple[float, ...]
    T_odom_base: NDArray[np.float64]
    config: PipelineConfig
    config_hash: str
    pipeline_version: str
    optimisation: OptimisationResult
    rough_refinement: RoughRefinementResult | None
    warnings: tuple[str, ...] = ()

    @property
    def passed(self) -> bool:
        return self.verdict.passed

    def lidar(self, frame: str) -> LidarCalibration:
        for lidar in self.lidars:
            if lidar.frame == frame:
                return lidar
        raise KeyError(f"no LiDAR {frame!r}; calibrated: {[x.frame for x in self.lidars]}")

    def T_base_lidar_per_iteration(self, frame: str) -> NDArray[np.float64]:
        """(K + 1, 4, 4): this LiDAR's `T_base_lidar` before each stage-4 step and at the end
        (the reference's `T_base_ref` as calibrated)."""
        index = [x.frame for x in self.lidars].index(frame)
        T_base_ref = self.lidars[0].T_base_lidar_calibrated
        history: NDArray[np.float64] = (
            T_base_ref @ self.optimisation.T_ref_lidar_per_iteration[:, index]
        )
        return history


# -- set-up shared with the baselines --------------------------------------------------------


@dataclass(frozen=True)
class Prepared:
    """The problem in the calibration's own terms: LiDARs reference first, clouds per LiDAR and
    stop as recorded with their floors (fitted before stage 1) and stage 1's keep masks (None:
    all kept), initial `T_G_ref` (J, 4, 4) and `T_ref_lidar` (L, 4, 4), and the expected floor
    normal ("up") in each LiDAR's frame from the initial extrinsics. `filtered` gives a cloud as
    stage 2 sees it."""

    lidars: tuple[LidarInfo, ...]
    clouds: tuple[tuple[Points, ...], ...]
    kept: tuple[tuple[KeepMask | None, ...], ...]
    T_G_ref: NDArray[np.float64]
    T_ref_lidar: NDArray[np.float64]
    up: tuple[NDArray[np.float64], ...]
    floors: tuple[tuple[FloorFit | None, ...], ...]
    input_points: int
    removed_points: int
    judged_points: int
    filtered_frames: tuple[str, ...]
    denoise_seconds: float
    floor_seconds: float
    removed_by_frame: dict[str, tuple[int, int]] = field(default_factory=dict)
    """Per filtered LiDAR frame: (points judged, points removed) by stage 1 over all stops."""

    def filtered(self, lidar: int, stop: int) -> tuple[Points, FloorFit | None]:
        """LiDAR `lidar`'s cloud at stop `stop` without what stage 1 removed, and its floor
        (inlier mask over those points). Copied here, one at a time: a full-rate recording's
        filtered clouds all at once would be hundreds of MB."""
        cloud, floor = self.clouds[lidar][stop], self.floors[lidar][stop]
        keep = self.kept[lidar][stop]
        if keep is None:
            return cloud, floor
        return cloud[keep], None if floor is None else (floor[0], floor[1][keep], floor[2])


def order_lidars(problem: CalibrationProblem, frames: FramesConfig) -> tuple[LidarInfo, ...]:
    """The LiDARs with the reference first (the configured one, else the first frame sorted)."""
    if len(problem.lidars) < 2:
        raise BadInputError(
            f"calibration needs at least two LiDARs; the recording has {list(problem.frames)}"
        )
    if len(problem.stops) < 2:
        raise BadInputError(
            f"calibration needs at least two stops; the recording has {len(problem.stops)} "
            "(the robot must stop, move and stop again while the LiDARs record)"
        )
    others = sorted(problem.lidars, key=lambda lidar: lidar.frame)
    name = frames.reference_frame or others[0].frame
    if name not in problem.frames:
        raise BadInputError(
            f"reference LiDAR {name!r} is not in the recording; its LiDAR frames are "
            f"{sorted(problem.frames)}"
        )
    reference = problem.lidar(name)
    return (reference, *[lidar for lidar in others if lidar.frame != name])


def prepare(
    problem: CalibrationProblem, config: PipelineConfig, *, denoised: bool = True
) -> Prepared:
    """Order the LiDARs, fit each cloud's floor, run stage 1 (when `denoised` and enabled) and set
    up the initial poses.

    Stage 1 judges only the points standing above the floor (the object candidates, a tenth of a
    full-rate cloud): bleeding points elsewhere never reach the later stages, and judging all
    would cost ten times as much. Their neighbours are searched among every point. Clouds stay at
    full rate: segmentation voxelises only what stands above the floor. Only non-repetitive
    LiDARs' clouds are filtered (see `stage_1_filters`)."""
    lidars = order_lidars(problem, config.frames)
    T_base_ref = lidars[0].T_base_lidar
    T_odom_ref0 = problem.stops[0].T_odom_base @ T_base_ref
    T_G_odom = invert(T_odom_ref0)
    T_G_ref = np.stack([T_G_odom @ stop.T_odom_base @ T_base_ref for stop in problem.stops])
    T_ref_base = invert(T_base_ref)
    T_ref_lidar = np.stack([T_ref_base @ lidar.T_base_lidar for lidar in lidars])
    T_ref_lidar[0] = np.eye(4)
    up = tuple(lidar.T_base_lidar[:3, :3].T @ np.array([0.0, 0.0, 1.0]) for lidar in lidars)
    clouds, floors, kept_masks = [], [], []
    counts = {"input": 0, "removed": 0, "judged": 0}
    seconds = {"floor": 0.0, "denoise": 0.0}
    by_frame: dict[str, tuple[int, int]] = {}
    filtered_frames = tuple(
        lidar.frame for lidar in lidars if denoised and stage_1_filters(lidar, config.denoise)
    )
    for lidar, lidar_up in zip(lidars, up, strict=True):
        row, row_floors, row_kept = [], [], []
        run_stage_1 = lidar.frame in filtered_frames
        for stop in problem.stops:
            cloud = np.asarray(stop.clouds.get(lidar.frame, np.zeros((0, 3))), dtype=np.float64)
            counts["input"] += len(cloud)
            started = time.perf_counter()
            floor = fit_floor(cloud, lidar_up, config.segmentation)
            seconds["floor"] += time.perf_counter() - started
            keep = None
            if run_stage_1 and floor is not None:
                kept = denoise_above_floor(cloud, floor[0], config, lidar.frame)
                seconds["denoise"] += kept.seconds
                counts["judged"] += kept.judged_points
                counts["removed"] += kept.removed_points
                judged, removed = by_frame.get(lidar.frame, (0, 0))
                by_frame[lidar.frame] = (judged + kept.judged_points, removed + kept.removed_points)
                keep = kept.keep if kept.removed_points else None
            row.append(cloud)
            row_floors.append(floor)
            row_kept.append(keep)
        clouds.append(tuple(row))
        floors.append(tuple(row_floors))
        kept_masks.append(tuple(row_kept))
    return Prepared(
        lidars,
        tuple(clouds),
        tuple(kept_masks),
        T_G_ref,
        T_ref_lidar,
        up,
        tuple(floors),
        counts["input"],
        counts["removed"],
        counts["judged"],
        filtered_frames,
        seconds["denoise"],
        seconds["floor"],
        by_frame,
    )


def stage_1_filters(lidar: LidarInfo, config: DenoiseConfig) -> bool:
    """Whether stage 1 filters this LiDAR's clouds: when enabled, for non-repetitive scans only.

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
    return config.enabled and pattern is ScanPattern.NON_REPETITIVE


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


def _denoise_message(prepared: Prepared, config: DenoiseConfig) -> str:
    if not config.enabled:
        return "disabled"
    unfiltered = [f for f in prepared.lidars if f.frame not in prepared.filtered_frames]
    reasons = {ScanPattern.UNKNOWN: "scan pattern unknown"}
    by_reason: dict[str, list[str]] = {}
    for lidar in unfiltered:
        pattern = config.scan_patterns.get(lidar.frame, lidar.scan_pattern)
        by_reason.setdefault(reasons.get(pattern, "repetitive scans"), []).append(lidar.frame)
    left_alone = "; ".join(
        f"{', '.join(frames)} not filtered ({reason})" for reason, frames in by_reason.items()
    )
    if not prepared.filtered_frames:
        return left_alone
    message = (
        f"removed {prepared.removed_points} of the {prepared.judged_points} points above the floor"
    )
    return f"{message}; {left_alone}" if unfiltered else message


def segment_all(prepared: Prepared, config: PipelineConfig) -> tuple[tuple[Segmentation, ...], ...]:
    def segmented(lidar: int, stop: int) -> Segmentation:
        cloud, floor = prepared.filtered(lidar, stop)
        return segment_on_floor(cloud, config.segmentation, floor)

    return tuple(
        tuple(segmented(lidar, stop) for stop in range(len(row)))
        for lidar, row in enumerate(prepared.clouds)
    )


def floor_pose(T_base_ref: Matrix4, floor_ref: Plane, height_m: float) -> Matrix4:
    """`T_base_ref` with height, roll and pitch from the floor (seen in the reference frame):
    base z along the floor normal, base origin `height_m` above the floor; x, y, yaw kept."""
    R_level = level_rotation(T_base_ref[:3, :3] @ floor_ref.normal)
    T = make_transform(R_level @ T_base_ref[:3, :3], R_level @ T_base_ref[:3, 3])
    # In the base frame the floor is z = -height: the reference origin is `offset` above it.
    T[2, 3] = floor_ref.offset - height_m
    return T


@contextmanager
def _timed(
    stages: dict[str, StageReport],
    name: str,
    details: dict[str, float | int | bool | str],
    extra_seconds: float = 0.0,
) -> Iterator[None]:
    started = time.perf_counter()
    yield
    stages[name] = StageReport(time.perf_counter() - started + extra_seconds, details)


def calibrate(
    problem: CalibrationProblem,
    config: PipelineConfig | None = None,
    progress: Progress | None = None,
    on_iteration: IterationProgress | None = None,
) -> CalibrationResult:
    """Calibrate every LiDAR of `problem` relative to the reference; see `CalibrationResult`.

    Raises `BadInputError` when the problem cannot be calibrated at all (fewer than two LiDARs
    or stops, an unknown reference, no floor anywhere). Data that are merely poor (no objects,
    no convergence) give a result whose verdict fails, with the failed checks named.
    """
    from pipeline import __version__

    config = config or PipelineConfig()
    stages: dict[str, StageReport] = {}

    def report(stage: str, message: str) -> None:
        if progress is not None:
            progress(stage, stages[stage].seconds, message)

    prepared = prepare(problem, config)
    stages["denoise"] = StageReport(
        prepared.denoise_seconds,
        {
            "input_points": prepared.input_points,
            "judged_points": prepared.judged_points,
            "removed_points": prepared.removed_points,
            "enabled": config.denoise.enabled,
            "filtered_frames": ",".join(prepared.filtered_frames),
            "method": str(config.denoise.method),
            **{
                f"{count}.{frame}": value
                for frame, pair in prepared.removed_by_frame.items()
                for count, value in zip(("judged_points", "removed_points"), pair, strict=True)
            },
        },
    )
    report("denoise", _denoise_message(prepared, config.denoise))

    # The floors were fitted before stage 1 (it judges what stands on them): their time counts here.
    details: dict[str, float | int | bool | str] = {"floor_seconds": prepared.floor_seconds}
    with _timed(stages, "segmentation", details, extra_seconds=prepared.floor_seconds):
        segments = segment_all(prepared, config)
        objects = [[s.object_points for s in row] for row in segments]
        normals = [[s.object_normals for s in row] for row in segments]
        planes: list[list[Plane | None]] = [[s.floor for s in row] for row in segments]
        object_points = [sum(len(s.object_points) for s in row) for row in segments]
        details.update(
            object_points=sum(object_points),
            floor_planes=sum(p is not None for row in planes for p in row),
            clusters=sum(s.cluster_count for row in segments for s in row),
        )
    report(
        "segmentation",
        f"{details['object_points']} object points, {details['floor_planes']} floor planes",
    )

    T_G_ref, T_ref_lidar = prepared.T_G_ref, prepared.T_ref_lidar
    metric_initial = metric_error(objects, T_G_ref, T_ref_lidar, config.metric)

    rough: RoughRefinementResult | None = None
    details = {}
    with _timed(stages, "rough_refinement", details):
        details["enabled"] = config.rough_refinement.enabled
        if config.rough_refinement.enabled:
            rough = refine_with_floor(planes, T_G_ref, T_ref_lidar, config.rough_refinement)
            T_G_ref, T_ref_lidar = rough.T_G_ref, rough.T_ref_lidar
            details.update(
                iterations=rough.iterations,
                converged=rough.converged,
                planes=rough.observations,
                tilt_rms_deg_initial=rough.residual_initial.tilt_deg,
                tilt_rms_deg_final=rough.residual_final.tilt_deg,
                offset_rms_m_initial=rough.residual_initial.offset_m,
                offset_rms_m_final=rough.residual_final.offset_m,
            )
    report(
        "rough_refinement",
        "skipped"
        if rough is None
        else f"{rough.observations} floor planes agree to {rough.residual_final.tilt_deg:.3f} deg"
        f" / {rough.residual_final.offset_m * 1000:.1f} mm",
    )

    details = {}
    with _timed(stages, "optimisation", details):
        result = optimise(
            objects,
            T_G_ref,
            T_ref_lidar,
            config.optimisation,
            planes=planes if rough is not None else None,
            floor_G=rough.floor_G if rough is not None else None,
            normals=normals,
            on_iteration=None
            if on_iteration is None
            else partial(_iteration_of, on_iteration, config.optimisation.max_iterations),
        )
        details.update(
            iterations=result.iterations,
            converged=result.converged,
            residual=config.optimisation.residual,
            residual_rms_m=result.residual_rms_m,
        )
    report(
        "optimisation",
        f"{result.iterations} iterations, {'converged' if result.converged else 'NOT converged'}",
    )

    details = {}
    with _timed(stages, "metric", details):
        metric_final = metric_error(objects, result.T_G_ref, result.T_ref_lidar, config.metric)
        details.update(initial_m=metric_initial.value, final_m=metric_final.value)
    report("metric", f"{metric_initial.value:.4f} m -> {metric_final.value:.4f} m")

    # Where the floor lies in the reference frame (G is the reference at stop 0).
    floor_ref: Plane | None = None
    if rough is not None:
        normal = result.T_G_ref[0][:3, :3].T @ rough.floor_G.normal
        offset = rough.floor_G.offset + float(rough.floor_G.normal @ result.T_G_ref[0][:3, 3])
        floor_ref = Plane(normal=normal, offset=offset)
    T_base_ref = prepared.lidars[0].T_base_lidar
    height = config.frames.base_height_above_floor_m
    if height is not None and floor_ref is not None:
        T_base_ref = floor_pose(T_base_ref, floor_ref, height)

    details = {}
    with _timed(stages, "observability", details):
        uncertainties = pose_uncertainties(
            result,
            T_base_ref,
            None if floor_ref is None else floor_ref.normal,
            config.observability,
        )
        details["undetermined"] = sum(len(u.undetermined) for u in uncertainties)
    report("observability", _undetermined_message(prepared.lidars, uncertainties))

    lidars = tuple(
        LidarCalibration(
            frame=info.frame,
            topic=info.topic,
            is_reference=index == 0,
            T_base_lidar_initial=info.T_base_lidar,
            T_base_lidar_calibrated=T_base_ref @ result.T_ref_lidar[index],
            uncertainty=uncertainties[index],
            object_points=object_points[index],
            metric_initial=metric_initial.per_lidar[index],
            metric_final=metric_final.per_lidar[index],
        )
        for index, info in enumerate(prepared.lidars)
    )
    details = {}
    with _timed(stages, "verdict", details):
        verdict = judge(
            metric_final.value,
            result.converged,
            result.iterations,
            config.optimisation.max_iterations,
            [_evidence(lidar) for lidar in lidars],
            config.verdict,
        )
        details["failed_checks"] = len(verdict.failed)
    report(
        "verdict",
        "PASSED" if verdict.passed else f"FAILED: {', '.join(c.name for c in verdict.failed)}",
    )

    T_odom_G = problem.stops[0].T_odom_base @ prepared.lidars[0].T_base_lidar
    T_ref_base = invert(prepared.lidars[0].T_base_lidar)
    T_odom_base = np.stack([T_odom_G @ T @ T_ref_base for T in result.T_G_ref])
    return CalibrationResult(
        reference_frame=prepared.lidars[0].frame,
        base_frame=problem.base_frame,
        lidars=lidars,
        metric_error_initial=metric_initial.value,
        metric_error_final=metric_final.value,
        verdict=verdict,
        stages=stages,
        converged=result.converged,
        iterations=result.iterations,
        error_per_iteration=result.error_per_iteration,
        T_odom_base=T_odom_base,
        config=config,
        config_hash=config_hash(config),
        pipeline_version=__version__,
        optimisation=result,
        rough_refinement=rough,
        warnings=(
            *(problem.recording.warnings if problem.recording is not None else ()),
            *unknown_frame_warnings(config, problem.frames),
        ),
    )


def _evidence(lidar: LidarCalibration) -> LidarEvidence:
    translation, rotation = lidar.change
    t = lidar.uncertainty.stddev_translation_m
    r = lidar.uncertainty.stddev_rotation_deg
    return LidarEvidence(
        frame=lidar.frame,
        is_reference=lidar.is_reference,
        object_points=lidar.object_points,
        stddev_translation_m=(float(t[0]), float(t[1]), float(t[2])),
        stddev_rotation_deg=(float(r[0]), float(r[1]), float(r[2])),
        undetermined=lidar.uncertainty.undetermined,
        deviation_translation_m=translation,
        deviation_rotation_deg=rotation,
    )


def _undetermined_message(
    lidars: Sequence[LidarInfo], uncertainties: Sequence[PoseUncertainty]
) -> str:
    missing = [
        f"{info.frame}: {', '.join(u.undetermined)}"
        for info, u in zip(lidars, uncertainties, strict=True)
        if u.undetermined
    ]
    return (
        "every degree of freedom determined"
        if not missing
        else "undetermined " + "; ".join(missing)
    )
