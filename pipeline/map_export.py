"""The accumulated map before and after calibration as a PLY or PCD point cloud, one colour per
LiDAR (the report's colours), for CloudCompare, RViz or Foxglove.

Both maps are in W, the base frame at the first stop (as the report images): before with the
odometry's stop poses and the initial extrinsics, after with the result's refined stop poses
(`stops[].T_odom_base`) and calibrated extrinsics. The same points enter both.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.colors import to_rgb
from numpy.typing import NDArray

from pipeline.export import ExportError, MapFormat, calibrated_extrinsics
from pipeline.problem import CalibrationProblem
from pipeline.report import LIDAR_COLOURS, map_poses
from pipeline.transforms import Matrix4, from_translation_xyzw


@dataclass(frozen=True)
class ColouredMap:
    """(N, 3) points in W, (N, 3) RGB in [0, 1], and (N,) LiDAR index into `frames`."""

    frames: tuple[str, ...]
    points: NDArray[np.float64]
    colours: NDArray[np.float64]
    lidar: NDArray[np.int64]


def maps_before_after(
    problem: CalibrationProblem,
    document: Mapping[str, Any],
    *,
    allow_failed: bool = False,
    max_points: int = 2_000_000,
    seed: int = 0,
) -> tuple[ColouredMap, ColouredMap]:
    """The map before and after calibration of `problem` (read from the recording `document`
    was calibrated from); at most about `max_points` points each, the same subset in both."""
    extrinsics = calibrated_extrinsics(document, allow_failed=allow_failed)
    frames = tuple(edge.child for edge in extrinsics)
    missing = sorted(set(frames) - set(problem.frames))
    if missing:
        raise ExportError(
            f"the recording has no LiDAR {', '.join(missing)}; pass the recording this result "
            "was calibrated from"
        )
    refined = _refined_stops(document, len(problem.stops))
    odometry = np.stack([stop.T_odom_base for stop in problem.stops])
    before = map_poses(odometry, [problem.lidar(frame).T_base_lidar for frame in frames])
    after = map_poses(refined, [edge.matrix() for edge in extrinsics])
    total = sum(stop.clouds[f].shape[0] for stop in problem.stops for f in frames)
    keep = min(1.0, max_points / max(total, 1))
    rng = np.random.default_rng(seed)
    clouds = [
        [_subset(stop.clouds[frame], keep, rng) for stop in problem.stops] for frame in frames
    ]
    return _placed(frames, clouds, before), _placed(frames, clouds, after)


def write_map(path: Path, cloud: ColouredMap, fmt: MapFormat | str) -> Path:
    """Write `cloud` to `path` as binary PLY or PCD (open3d); `path` must not exist."""
    import open3d as o3d

    fmt = MapFormat(fmt)
    if path.exists():
        raise ExportError(f"{path} already exists; choose a new path")
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.points))
    pcd.colors = o3d.utility.Vector3dVector(cloud.colours)
    target = path if path.suffix == f".{fmt.value}" else path.with_name(f"{path.name}.{fmt.value}")
    if not o3d.io.write_point_cloud(target, pcd, write_ascii=False):
        raise ExportError(f"cannot write {target}; check that its folder exists and is writable")
    return target


def _refined_stops(document: Mapping[str, Any], expected: int) -> NDArray[np.float64]:
    stops = document.get("stops")
    if not isinstance(stops, list) or len(stops) != expected:
        found = len(stops) if isinstance(stops, list) else 0
        raise ExportError(
            f"the result has {found} refined stop poses but the recording {expected} stops; pass "
            "the recording this result was calibrated from, read with the same config"
        )
    try:
        return np.stack(
            [
                from_translation_xyzw(
                    s["T_odom_base"]["translation"], s["T_odom_base"]["rotation_xyzw"]
                )
                for s in stops
            ]
        )
    except (KeyError, TypeError, ValueError) as err:
        raise ExportError(f"the result's stop poses are damaged ({err})") from None


def _subset(
    points: NDArray[np.float64], keep: float, rng: np.random.Generator
) -> NDArray[np.float64]:
    if keep >= 1.0:
        return points
    kept: NDArray[np.float64] = points[rng.random(points.shape[0]) < keep]
    return kept


def _placed(
    frames: tuple[str, ...], clouds: list[list[NDArray[np.float64]]], T_W_lidar: NDArray[np.float64]
) -> ColouredMap:
    points, lidar = [], []
    for i, row in enumerate(clouds):
        for cloud, T in zip(row, T_W_lidar[i], strict=True):
            points.append(_apply(T, cloud))
            lidar.append(np.full(cloud.shape[0], i, dtype=np.int64))
    index = np.concatenate(lidar) if lidar else np.zeros(0, dtype=np.int64)
    palette = np.array([to_rgb(LIDAR_COLOURS[i % len(LIDAR_COLOURS)]) for i in range(len(frames))])
    return ColouredMap(
        frames=frames,
        points=np.concatenate(points) if points else np.zeros((0, 3)),
        colours=palette[index],
        lidar=index,
    )


def _apply(T: Matrix4, points: NDArray[np.float64]) -> NDArray[np.float64]:
    result: NDArray[np.float64] = points @ T[:3, :3].T + T[:3, 3]
    return result
