"""The verdict: each LiDAR's outcome put together, then every check of `pipeline.verdict`."""

from __future__ import annotations

import dataclasses

from pipeline.config import PipelineConfig
from pipeline.stages.runner import Listeners, StageOutcome
from pipeline.stages.state import CalibrationState, LidarCalibration, required
from pipeline.verdict import LidarEvidence, judge


def lidar_calibrations(state: CalibrationState) -> tuple[LidarCalibration, ...]:
    """Every LiDAR's outcome, reference first: `T_base_lidar = T_base_ref @ T_ref_lidar`."""
    T_base_ref = required(state.T_base_ref_calibrated, "observability")
    uncertainties = required(state.uncertainties, "observability")
    initial = required(state.metric_initial, "metric")
    final = required(state.metric_final, "metric")
    seen = required(state.metric_seen, "metric")
    objects = state.objects_in_lidar()
    return tuple(
        LidarCalibration(
            frame=info.frame,
            topic=info.topic,
            is_reference=index == 0,
            T_base_lidar_initial=info.T_base_lidar,
            T_base_lidar_calibrated=T_base_ref @ state.T_ref_lidar[index],
            uncertainty=uncertainties[index],
            object_points=sum(len(points) for points in objects[index]),
            metric_initial=initial.per_lidar[index],
            metric_final=final.per_lidar[index],
            seen_metric_final=seen.per_lidar[index],
            seen_points=seen.seen[index],
        )
        for index, info in enumerate(state.lidars)
    )


def evidence(lidar: LidarCalibration) -> LidarEvidence:
    """What the verdict judges of one LiDAR."""
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
        seen_metric_error_m=lidar.seen_metric_final,
        seen_points=lidar.seen_points,
    )


def run(state: CalibrationState, config: PipelineConfig, listeners: Listeners) -> StageOutcome:
    """Judge the calibration: the metric, convergence and every LiDAR's evidence."""
    calibrations = lidar_calibrations(state)
    optimised = required(state.optimised, "optimisation")
    verdict = judge(
        required(state.metric_final, "metric").value,
        optimised.converged,
        optimised.iterations,
        config.optimisation.max_iterations,
        [evidence(lidar) for lidar in calibrations],
        config.verdict,
        starts=state.starts_evidence(),
    )
    message = "PASSED" if verdict.passed else f"FAILED: {', '.join(c.name for c in verdict.failed)}"
    return StageOutcome(
        dataclasses.replace(state, calibrations=calibrations, verdict=verdict),
        {"failed_checks": len(verdict.failed)},
        message,
    )
