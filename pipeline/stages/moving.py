"""Before stage 1: the points that moved within their stop (people, carts walking by) leave each
stop cloud (`pipeline.moving_points`), so that no later stage fits a floor, an object or a pair to
them. What was removed is reported per LiDAR."""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.config import PipelineConfig
from pipeline.moving_points import MovingPointsConfig, find_moving_points, scan_ids
from pipeline.stages.runner import Listeners, StageOutcome
from pipeline.stages.state import CalibrationState, Detail, per_cloud
from pipeline.transforms import Points


def run(state: CalibrationState, config: PipelineConfig, listeners: Listeners) -> StageOutcome:
    """Remove the moving points of every stop cloud whose scans are known and numerous enough."""
    settings = config.moving_points
    clouds: list[tuple[Points, ...]] = []
    sizes: list[tuple[tuple[int, ...], ...]] = []
    details: dict[str, Detail] = {"enabled": settings.enabled}
    judged = skipped = total = 0
    unknown = tuple(((),) * len(row) for row in state.clouds_in_lidar)
    all_sizes = state.scan_sizes or unknown

    def without_moving(at: tuple[int, int]) -> tuple[Points, tuple[int, ...], int | None]:
        lidar, stop = at
        return _without_moving(state.clouds_in_lidar[lidar][stop], all_sizes[lidar][stop], settings)

    outcomes = per_cloud(state.clouds_in_lidar, without_moving)
    for lidar, row, row_outcomes in zip(state.lidars, state.clouds_in_lidar, outcomes, strict=True):
        kept_row, sizes_row, removed = [], [], 0
        for cloud, (kept, kept_sizes, moving) in zip(row, row_outcomes, strict=True):
            kept_row.append(kept)
            sizes_row.append(kept_sizes)
            if moving is None:
                # Not judged: its scans are unknown or too few (an empty cloud has nothing).
                skipped += settings.enabled and len(cloud) > 0
            else:
                judged += 1
                removed += moving
        clouds.append(tuple(kept_row))
        sizes.append(tuple(sizes_row))
        details[f"removed_points.{lidar.frame}"] = removed
        total += removed
    details.update(removed_points=total, judged_clouds=judged, skipped_clouds=skipped)
    new_state = dataclasses.replace(state, clouds_in_lidar=tuple(clouds), scan_sizes=tuple(sizes))
    return StageOutcome(
        new_state,
        details,
        f"{total} moving points removed from {judged} stop clouds ({skipped} not judged)",
    )


def _without_moving(
    cloud: Points, scan_sizes: tuple[int, ...], settings: MovingPointsConfig
) -> tuple[Points, tuple[int, ...], int | None]:
    """One stop cloud without its moving points, its scans' new sizes, and how many points
    moved (None: the cloud was not judged, and comes back as it was)."""
    found = (
        find_moving_points(cloud, scan_sizes, settings) if settings.enabled and scan_sizes else None
    )
    if found is None or found.skipped:
        return cloud, scan_sizes, None
    if not found.moving.any():
        return cloud, scan_sizes, 0
    keep = ~found.moving
    kept_sizes = np.bincount(scan_ids(scan_sizes)[keep], minlength=len(scan_sizes))
    return cloud[keep], tuple(int(n) for n in kept_sizes), int(found.moving.sum())
