"""Points that move within a stop (people, carts walking by): found and removed before the stages.

The robot stands still during a stop, so a static surface returns from the same place in every
scan of the stop, while a person walking by is somewhere else in each. Two tests, in the LiDAR's
own frame, on one stop's scans:

- **seen through**: a direction in which another scan of the stop returned from farther away (by
  `range_margin_m` plus `range_margin_fraction` of the range) was empty at that range then: the
  point was not there for the whole stop. Directions are compared in cells of
  `direction_cell_deg` on the unit sphere (by default the spacing of one scan's directions, so a
  cell holds about one point a scan), against the farthest return of each other scan.
  Alone this also fires at depth edges and on mixed returns between two surfaces;
- **seen once**: among a point's `temporal_neighbours` nearest points of the stop's cloud, few
  come from other scans (at most `max_scan_share` of the scans): a static surface is hit again by
  later scans, a moving one is not.

A point that passes both tests seeds its scan's moving blob, which grows through that scan's
points within `grow_radius_m` while they are seen rarely (at most `grow_scan_share` of the scans;
a floor or a wall under a person's feet is seen by every scan, and stops the growth). A stop with
fewer than `min_scans` scans keeps every point: it cannot tell a person from a box.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field
from pykdtree.kdtree import KDTree

from pipeline.geometry import voxel_keys

Points = NDArray[np.float64]
Mask = NDArray[np.bool_]

_MIN_CELL_DEG, _MAX_CELL_DEG = 0.01, 5.0


class MovingPointsConfig(BaseModel):
    """Removal of points that move within a stop; angles in degrees, lengths in metres."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    enabled: bool = Field(default=True, description="remove points that move within a stop")
    min_scans: int = Field(
        default=4, ge=2, description="stops with fewer scans per LiDAR keep every point"
    )
    direction_cell_deg: float | None = Field(
        default=None,
        ge=0.01,
        le=5,
        description="directions compared in cells of this size; None: the median angle between "
        "neighbouring directions of one scan (so that each cell holds about one point a scan)",
    )
    range_margin_m: float = Field(
        default=0.1, ge=0, description="a return this much farther in the same cell sees through"
    )
    range_margin_fraction: float = Field(
        default=0.03, ge=0, description="plus this fraction of the point's range"
    )
    temporal_neighbours: int = Field(
        default=24, ge=2, description="nearest points whose scans are counted"
    )
    max_scan_share: float = Field(
        default=0.25, gt=0, le=1, description="a seed's neighbours come from at most this share"
    )
    grow_scan_share: float = Field(
        default=0.5, gt=0, le=1, description="a grown point's neighbours come from at most this"
    )
    grow_radius_m: float = Field(default=0.1, gt=0, description="a moving blob's reach per step")
    grow_steps: int = Field(default=10, ge=0, description="growth steps from the seeds")


@dataclass(frozen=True)
class MovingPoints:
    """One LiDAR in one stop: `moving[i]` for point i of the stop's cloud; `seeds` passed both
    tests (the rest were grown from them)."""

    moving: Mask
    seeds: int
    skipped: bool
    """The stop had too few scans to judge (every point kept)."""


def scan_ids(scan_sizes: Sequence[int]) -> NDArray[np.int64]:
    """The scan index of each point of a cloud concatenated from scans of these sizes."""
    return np.repeat(np.arange(len(scan_sizes), dtype=np.int64), np.asarray(scan_sizes, int))


def find_moving_points(
    points_in_lidar: Points, scan_sizes: Sequence[int], config: MovingPointsConfig
) -> MovingPoints:
    """Which points of one LiDAR's stop cloud (its scans concatenated in order, `scan_sizes`
    points each, in the LiDAR's frame) moved during the stop."""
    if sum(scan_sizes) != len(points_in_lidar):
        raise ValueError(
            f"scan sizes add up to {sum(scan_sizes)} points, the cloud has {len(points_in_lidar)}"
        )
    n_scans = sum(1 for size in scan_sizes if size > 0)
    none = np.zeros(len(points_in_lidar), dtype=bool)
    if n_scans < config.min_scans or not config.enabled:
        return MovingPoints(none, 0, skipped=n_scans < config.min_scans)
    scan = scan_ids(scan_sizes)
    candidates = np.flatnonzero(_seen_through(points_in_lidar, scan, config))
    if len(candidates) == 0:
        return MovingPoints(none, 0, skipped=False)
    tree = KDTree(points_in_lidar)
    seeds = candidates[
        _scan_share(tree, points_in_lidar, scan, candidates, n_scans, config)
        <= config.max_scan_share
    ]
    moving = none.copy()
    moving[seeds] = True
    _grow(points_in_lidar, scan, moving, tree, n_scans, config)
    return MovingPoints(moving, len(seeds), skipped=False)


def _seen_through(points: Points, scan: NDArray[np.int64], config: MovingPointsConfig) -> Mask:
    """Whether another scan returned from farther away in the same direction cell."""
    ranges = np.linalg.norm(points, axis=1)
    directions = points / np.maximum(ranges, 1e-9)[:, None]
    cell_size = np.radians(config.direction_cell_deg or _scan_spacing_deg(directions, scan))
    cell = voxel_keys(directions, cell_size, "moving_points.direction_cell_deg")
    # Per cell, the farthest return and its scan, then the farthest of every other scan.
    order = np.argsort(cell, kind="stable")
    cell_sorted, ranges_sorted, scan_sorted = cell[order], ranges[order], scan[order]
    new_cell = np.r_[True, cell_sorted[1:] != cell_sorted[:-1]]
    starts = np.flatnonzero(new_cell)
    group = np.cumsum(new_cell) - 1
    farthest = np.maximum.reduceat(ranges_sorted, starts)[group]
    farthest_scan = np.empty(len(starts), dtype=np.int64)
    is_farthest = ranges_sorted == farthest
    farthest_scan[group[is_farthest]] = scan_sorted[is_farthest]
    other_scan = scan_sorted != farthest_scan[group]
    runner_up = np.maximum.reduceat(np.where(other_scan, ranges_sorted, -np.inf), starts)[group]
    farther_elsewhere = np.empty_like(ranges)
    farther_elsewhere[order] = np.where(other_scan, farthest, runner_up)
    margin = config.range_margin_m + config.range_margin_fraction * ranges
    seen_through: Mask = farther_elsewhere > ranges + margin
    return seen_through


def _scan_spacing_deg(directions: Points, scan: NDArray[np.int64]) -> float:
    """The median angle between a direction and its nearest neighbour within the same scan (the
    largest), clipped to the cell sizes the config allows."""
    largest = np.bincount(scan).argmax()
    own = directions[scan == largest]
    distance, _ = KDTree(own).query(own, k=2)
    spacing = float(np.degrees(np.median(distance[:, 1]))) if len(own) > 1 else 1.0
    return float(np.clip(spacing, _MIN_CELL_DEG, _MAX_CELL_DEG))


def _scan_share(
    tree: KDTree,
    points: Points,
    scan: NDArray[np.int64],
    which: NDArray[np.intp],
    n_scans: int,
    config: MovingPointsConfig,
) -> NDArray[np.float64]:
    """For points `which`: how many distinct scans their nearest neighbours come from, as a share
    of what a static surface would give (every scan, or every neighbour if fewer)."""
    k = min(config.temporal_neighbours, len(points))
    _, neighbours = tree.query(points[which], k=k)
    scans_of = np.sort(scan[np.asarray(neighbours).reshape(len(which), k)], axis=1)
    distinct = 1 + np.count_nonzero(np.diff(scans_of, axis=1), axis=1)
    share: NDArray[np.float64] = distinct / min(k, n_scans)
    return share


def _grow(
    points: Points,
    scan: NDArray[np.int64],
    moving: Mask,
    tree: KDTree,
    n_scans: int,
    config: MovingPointsConfig,
) -> None:
    """Grow each scan's moving seeds through that scan's rarely seen points, in place."""
    for scan_index in np.unique(scan[moving]):
        members = np.flatnonzero(scan == scan_index)
        scan_tree = KDTree(points[members])
        frontier = members[moving[members]]
        judged = moving.copy()
        for _ in range(config.grow_steps):
            distance, local = scan_tree.query(
                points[frontier], k=8, distance_upper_bound=config.grow_radius_m
            )
            reached = members[np.unique(local[np.isfinite(distance)])]
            new = reached[~judged[reached]]
            if len(new) == 0:
                break
            judged[new] = True
            share = _scan_share(tree, points, scan, new, n_scans, config)
            frontier = new[share <= config.grow_scan_share]
            moving[frontier] = True
