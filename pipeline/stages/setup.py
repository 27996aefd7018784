"""The state before the first stage: the LiDARs reference first, their clouds and the initial
poses from the recording's odometry and extrinsics."""

from __future__ import annotations

import numpy as np

from pipeline.config import FramesConfig
from pipeline.errors import BadInputError
from pipeline.problem import CalibrationProblem, LidarInfo
from pipeline.stages.state import CalibrationState
from pipeline.transforms import invert


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


def initial_state(problem: CalibrationProblem, frames: FramesConfig) -> CalibrationState:
    """Order the LiDARs and set up the initial poses: `T_G_ref` from the odometry, `T_ref_lidar`
    from the recorded extrinsics. A LiDAR that saw nothing at a stop gets an empty cloud."""
    lidars = order_lidars(problem, frames)
    T_base_ref = lidars[0].T_base_lidar
    T_odom_ref0 = problem.stops[0].T_odom_base @ T_base_ref
    T_G_odom = invert(T_odom_ref0)
    T_G_ref = np.stack([T_G_odom @ stop.T_odom_base @ T_base_ref for stop in problem.stops])
    T_ref_base = invert(T_base_ref)
    T_ref_lidar = np.stack([T_ref_base @ lidar.T_base_lidar for lidar in lidars])
    T_ref_lidar[0] = np.eye(4)
    return CalibrationState(
        lidars=lidars,
        clouds_in_lidar=tuple(
            tuple(
                np.asarray(stop.clouds.get(lidar.frame, np.zeros((0, 3))), dtype=np.float64)
                for stop in problem.stops
            )
            for lidar in lidars
        ),
        scan_sizes=tuple(
            tuple(tuple(stop.scan_sizes.get(lidar.frame, ())) for stop in problem.stops)
            for lidar in lidars
        ),
        up_in_lidar=tuple(
            lidar.T_base_lidar[:3, :3].T @ np.array([0.0, 0.0, 1.0]) for lidar in lidars
        ),
        T_G_ref_initial=T_G_ref,
        T_ref_lidar_initial=T_ref_lidar,
        # Copies: a stage that refined the estimate in place would rewrite where it started.
        T_G_ref=T_G_ref.copy(),
        T_ref_lidar=T_ref_lidar.copy(),
    )
