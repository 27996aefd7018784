"""Clouds for the stage 1 tests: an analytic clean floor, and the synthesiser's labelled stops."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.problem import ScanPattern
from pipeline.synth.bleeding import BleedingCase

PITCH = np.radians(35.0)
HEIGHT = 0.5
AXIS = (1.0, 0.0, 0.0)
FLOOR_PLANE = np.array([-np.sin(PITCH), 0.0, np.cos(PITCH), HEIGHT])
"""The floor `[a, b, c, d]` in the LiDAR frame: world up, seen by a sensor pitched down."""
AXIS_ON_FLOOR = np.array([HEIGHT / np.sin(PITCH), 0.0, 0.0])
"""Where the optical axis (+x) meets that floor."""


def floor_in_lidar_frame(n: int, seed: int = 0, noise: float = 0.002) -> NDArray[np.float64]:
    """A clean floor seen by a LiDAR `HEIGHT` above it, pitched `PITCH` down, axis +x.

    Directions fill the Mid-70's 70.4 deg cone uniformly in off-axis angle, so the density falls
    away from the centre as a rosette's does; rays at or above the horizon and beyond 10 m are
    dropped.
    """
    rng = np.random.default_rng(seed)
    off_axis = rng.uniform(0.0, np.radians(35.2), n)
    azimuth = rng.uniform(-np.pi, np.pi, n)
    directions = np.column_stack(
        [np.cos(off_axis), np.sin(off_axis) * np.cos(azimuth), np.sin(off_axis) * np.sin(azimuth)]
    )
    down = -(directions @ FLOOR_PLANE[:3])
    hits = down > 0.05
    ranges = HEIGHT / down[hits] + rng.normal(0.0, noise, int(hits.sum()))
    points = directions[hits] * ranges[:, None]
    return np.asarray(points[ranges < 10.0], dtype=np.float64)


def veil(n: int, seed: int = 0) -> NDArray[np.float64]:
    """`n` mixed returns behind an edge: a sheet along the beams of a quarter circle of directions
    10 deg off-axis, at ranges spread between a foreground at 0.45 m and the floor behind."""
    rng = np.random.default_rng(seed)
    azimuth = rng.uniform(0.0, np.pi / 2.0, n)
    off_axis = np.radians(10.0)
    directions = np.column_stack(
        [
            np.full(n, np.cos(off_axis)),
            np.sin(off_axis) * np.cos(azimuth),
            np.sin(off_axis) * np.sin(azimuth),
        ]
    )
    floor_range = HEIGHT / -(directions @ FLOOR_PLANE[:3])
    ranges = rng.uniform(0.45, floor_range - 0.06)
    return np.asarray(directions * ranges[:, None], dtype=np.float64)


@dataclass(frozen=True)
class LabelledCloud:
    """One stop cloud of one LiDAR from the synthesiser: `points` (N, 3) in its frame,
    `is_bleeding` (N,), `optical_axis` (3,), `up` (3,): the floor normal expected in its frame
    from the initial extrinsics (what the pipeline's floor fit starts from)."""

    points: NDArray[np.float64]
    is_bleeding: NDArray[np.bool_]
    optical_axis: NDArray[np.float64]
    up: NDArray[np.float64]


def synth_stop_clouds(
    scenario: str, seeds: Sequence[int], stop_step: int = 1
) -> Iterator[LabelledCloud]:
    """The labelled stop clouds of a synthetic scenario, as `simulate_problem` hands them to the
    pipeline: every LiDAR, every `stop_step`-th stop, for each seed."""
    from pipeline.synth import simulate_problem

    for seed in seeds:
        problem, truth = simulate_problem(scenario, seed)
        for stop in problem.stops[::stop_step]:
            for lidar in problem.lidars:
                yield LabelledCloud(
                    stop.clouds[lidar.frame],
                    truth.stop_labels(stop.index, lidar.frame).is_bleeding,
                    np.asarray(truth.lidar(lidar.frame).optical_axis, dtype=np.float64),
                    lidar.T_base_lidar[:3, :3].T @ np.array([0.0, 0.0, 1.0]),
                )


def f_score(keep: NDArray[np.bool_], is_bleeding: NDArray[np.bool_]) -> float:
    """F-score of removal: positive = a removed point that is truly bleeding."""
    removed = ~keep
    true_pos = int(np.count_nonzero(removed & is_bleeding))
    false_pos = int(np.count_nonzero(removed & ~is_bleeding))
    false_neg = int(np.count_nonzero(keep & is_bleeding))
    return 2 * true_pos / max(2 * true_pos + false_pos + false_neg, 1)


@dataclass(frozen=True)
class BeamCloud:
    """A `LabelledCloud` rendered with a drawn bleeding model, with what its LiDAR model knows:
    `range_noise_m` and `scan_pattern` (what a config may give the filter); and, known only to
    the synthesiser, `surface_distance_m` (N,): each point's distance, as measured (range noise
    included), to the nearest true surface (the label's rule applied to the noisy point)."""

    cloud: LabelledCloud
    range_noise_m: float
    scan_pattern: ScanPattern
    surface_distance_m: NDArray[np.float64]


def bleeding_stop_clouds(case: BleedingCase, stops: Sequence[int] = (0, 8)) -> Iterator[BeamCloud]:
    """The stop clouds `stops` of every LiDAR of `case`'s scene, rendered with its beam."""
    from pipeline.synth import make_world

    world = make_world(case.scenario, case.scene_seed, bleeding=case.bleeding)
    for i, mount in enumerate(world.spec.lidars):
        up = world.T_base_lidar_initial[i][:3, :3].T @ np.array([0.0, 0.0, 1.0])
        pose_at = world.T_world_lidar(i)
        period_s = world.scan_period_ns(i) / 1e9
        for j in stops:
            scans, distances = [], []
            for k in world.stop_scans(i, j):
                scan = world.simulate_scan(i, k)
                # The robot stands still during a stop: one pose per scan.
                T_world_lidar = pose_at(np.array([k * period_s]))[0]
                placed = scan.points @ T_world_lidar[:3, :3].T + T_world_lidar[:3, 3]
                scans.append(scan)
                distances.append(world.scene.nearest_surface(placed)[0])
            cloud = LabelledCloud(
                np.concatenate([s.points for s in scans]),
                np.concatenate([s.is_bleeding for s in scans]),
                np.asarray(mount.model.optical_axis, dtype=np.float64),
                up,
            )
            yield BeamCloud(
                cloud,
                mount.model.range_noise_m,
                mount.model.scan_pattern,
                np.concatenate(distances),
            )
