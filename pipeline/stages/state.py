"""What the stages hand on to each other (`CalibrationState`) and what each reports.

Frames: G is the reference LiDAR's frame at stop 0 (`T_G_ref[0]` = identity, the gauge); the
unknowns are the reference's pose per stop `T_G_ref` and the extrinsics relative to it
`T_ref_lidar`; reported extrinsics are `T_base_lidar = T_base_ref @ T_ref_lidar`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from pipeline.denoise import KeepMask
from pipeline.geometry import Plane
from pipeline.metric import MetricError, SolutionComparison
from pipeline.observability import PoseUncertainty, SurfaceShift
from pipeline.optimisation import OptimisationResult
from pipeline.parallel import map_clouds
from pipeline.problem import LidarInfo
from pipeline.rough_refinement import RoughRefinementResult
from pipeline.segmentation import FloorFit, Segmentation
from pipeline.transforms import Matrix4, Points, pose_difference
from pipeline.verdict import StartsEvidence, Verdict
from pipeline.visibility import SeenMetric

_Value = TypeVar("_Value")

Detail = float | int | bool | str
"""One of a stage's details: a plain number, flag or word, for `result.json`."""


class StageOrderError(RuntimeError):
    """A stage needs what another stage makes, and that stage has not run: the declared sequence
    (`pipeline.stages.sequence.STAGE_SEQUENCE`) has them in the wrong order."""


def required(value: _Value | None, made_by: str) -> _Value:
    """`value`, which the stage `made_by` sets; a mistake in the stage sequence when missing."""
    if value is None:
        raise StageOrderError(
            f"this stage needs what stage {made_by!r} makes, and {made_by!r} has not run: put it "
            "before this one in STAGE_SEQUENCE (pipeline/stages/sequence.py)"
        )
    return value


@dataclass(frozen=True)
class StageReport:
    """Wall time of a stage and what it did (plain numbers and flags, for `result.json`)."""

    seconds: float
    details: Mapping[str, Detail] = field(default_factory=dict)


@dataclass(frozen=True)
class LidarCalibration:
    """One LiDAR's outcome. Transforms (4, 4) `T_base_lidar`; `metric_*` is eq. 12 over this
    LiDAR's points alone (NaN for the reference), `seen_metric_final` the mean distance of its
    points the reference saw from the reference's surfaces (`pipeline.visibility`), `seen_points`
    how many those were."""

    frame: str
    topic: str
    is_reference: bool
    T_base_lidar_initial: Matrix4
    T_base_lidar_calibrated: Matrix4
    uncertainty: PoseUncertainty
    object_points: int
    metric_initial: float
    metric_final: float
    seen_metric_final: float
    seen_points: int

    @property
    def change(self) -> tuple[float, float]:
        """Translation (m) and rotation (deg) from the initial to the calibrated extrinsics."""
        return pose_difference(self.T_base_lidar_initial, self.T_base_lidar_calibrated)


PerCloud = tuple[tuple[_Value, ...], ...]
"""One value per LiDAR (reference first) and stop: `x[lidar][stop]`."""


def per_cloud(
    clouds: PerCloud[Points], function: Callable[[tuple[int, int]], _Value]
) -> PerCloud[_Value]:
    """`function((lidar, stop))` for every cloud of `clouds`, spread over threads
    (`pipeline.parallel`): each cloud's work is its own."""
    shape = [len(row) for row in clouds]
    flat = map_clouds(function, [(i, j) for i, n in enumerate(shape) for j in range(n)])
    rows, start = [], 0
    for n in shape:
        rows.append(tuple(flat[start : start + n]))
        start += n
    return tuple(rows)


@dataclass(frozen=True)
class CalibrationState:
    """The calibration between two stages. Set up before the first (`setup.initial_state`); each
    stage returns a copy with what it made filled in (None: not made yet, see `required`).

    `clouds_in_lidar` are the stop clouds as recorded (not copied; the moving-points stage leaves
    them without what moved), `scan_sizes` the points of each scan in them (empty where the source
    did not say), `up_in_lidar` the expected
    floor normal in each LiDAR's frame from the initial extrinsics. `T_G_ref` (J, 4, 4) and
    `T_ref_lidar` (L, 4, 4) are the current estimate (stages 3 and 4 refine them), `*_initial`
    where they started. Stage 1 leaves `floors_in_lidar` (fitted before it: it judges what stands
    on them), its keep masks `kept` (None per cloud: all kept) and `floor_seconds` (the floors'
    time, which segmentation reports); `filtered(lidar, stop)` gives a cloud as stage 2 sees it.
    `floor_refinement` is None when stage 3 is disabled. `second_start` (`T_G_ref`,
    `T_ref_lidar`): another start for stage 4 (global alignment's candidate when it is to be
    judged after refinement), None when there is none. `metric_final` is the metric of the
    current poses: stage 4 leaves it where it chose between two starts by it (no stage after
    stage 4 moves the poses), the metric stage otherwise; `metric_seen` the seen metric of the
    current poses (`pipeline.visibility`). `start_comparison`: stage 4's two
    solutions side by side, None when it had one start. `surface_shift`: how far stage 4's
    solution moves on surfaces smoothed further, and what chance alone would move it (None: not
    measured, `pipeline.stages.sensitivity`)."""

    lidars: tuple[LidarInfo, ...]
    clouds_in_lidar: PerCloud[Points]
    up_in_lidar: tuple[NDArray[np.float64], ...]
    T_G_ref_initial: NDArray[np.float64]
    T_ref_lidar_initial: NDArray[np.float64]
    T_G_ref: NDArray[np.float64]
    T_ref_lidar: NDArray[np.float64]
    scan_sizes: PerCloud[tuple[int, ...]] = ()
    floors_in_lidar: PerCloud[FloorFit | None] | None = None
    kept: PerCloud[KeepMask | None] | None = None
    filtered_frames: tuple[str, ...] = ()
    floor_seconds: float = 0.0
    segments: PerCloud[Segmentation] | None = None
    floor_refinement: RoughRefinementResult | None = None
    second_start: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
    optimised: OptimisationResult | None = None
    metric_initial: MetricError | None = None
    metric_final: MetricError | None = None
    metric_seen: SeenMetric | None = None
    start_comparison: SolutionComparison | None = None
    surface_shift: SurfaceShift | None = None
    T_base_ref_calibrated: Matrix4 | None = None
    uncertainties: tuple[PoseUncertainty, ...] | None = None
    calibrations: tuple[LidarCalibration, ...] | None = None
    verdict: Verdict | None = None

    def starts_evidence(self) -> StartsEvidence | None:
        """Stage 4's two solutions side by side as the verdict judges them; None with one
        start."""
        compared = self.start_comparison
        if compared is None:
            return None
        return StartsEvidence(
            apart_translation_m=compared.apart_translation_m,
            apart_rotation_deg=compared.apart_rotation_deg,
            separation_sigmas=compared.separation_sigmas,
        )

    @property
    def T_base_ref_initial(self) -> Matrix4:
        """The reference LiDAR's extrinsics as recorded (tf_static or config)."""
        return self.lidars[0].T_base_lidar

    def filtered(self, lidar: int, stop: int) -> tuple[Points, FloorFit | None]:
        """LiDAR `lidar`'s cloud at stop `stop` without what stage 1 removed, and its floor
        (inlier mask over those points). Copied here, one at a time: a full-rate recording's
        filtered clouds all at once would be hundreds of MB."""
        cloud = self.clouds_in_lidar[lidar][stop]
        floor = required(self.floors_in_lidar, "denoise")[lidar][stop]
        keep = required(self.kept, "denoise")[lidar][stop]
        if keep is None:
            return cloud, floor
        return cloud[keep], None if floor is None else (floor[0], floor[1][keep], floor[2])

    def objects_in_lidar(self) -> PerCloud[Points]:
        """The object points segmentation kept, (N, 3) in each LiDAR's frame."""
        return tuple(
            tuple(s.object_points for s in row) for row in required(self.segments, "segmentation")
        )

    def object_normals_in_lidar(self) -> PerCloud[Points]:
        """The unit normal (N, 3) of each object point's local surface."""
        return tuple(
            tuple(s.object_normals for s in row) for row in required(self.segments, "segmentation")
        )

    def floors_seen(self) -> PerCloud[Plane | None]:
        """The floor plane segmentation found in each cloud (LiDAR frame), None where none."""
        return tuple(tuple(s.floor for s in row) for row in required(self.segments, "segmentation"))
