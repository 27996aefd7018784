"""Stage 1: remove bleeding points (mixed returns smeared from object edges towards the background).

`denoise(points, config, optical_axis)` is what the pipeline calls per LiDAR and stop; the
filters themselves (`filters`) and the observation centre (`centre`) are pure functions too.
"""

from __future__ import annotations

import enum
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import BaseModel, ConfigDict, Field, field_validator

from pipeline.denoise.centre import fit_floor_plane, observation_centre
from pipeline.denoise.filters import (
    KeepMask,
    Neighbours,
    Points,
    as_cloud,
    dsor_keep,
    dsor_mask,
    global_threshold,
    knn_mean_distances,
    nearest_neighbours,
    pattern_keep,
    pattern_mask,
    proposed_keep,
    proposed_mask,
    sor_keep,
    sor_mask,
)
from pipeline.denoise.range_gap import RangeGapSettings, range_gap_keep
from pipeline.errors import BadInputError
from pipeline.problem import ScanPattern

__all__ = [
    "DenoiseConfig",
    "DenoiseMethod",
    "DenoiseResult",
    "KeepMask",
    "as_cloud",
    "denoise",
    "dsor_mask",
    "fit_floor_plane",
    "global_threshold",
    "knn_mean_distances",
    "observation_centre",
    "pattern_mask",
    "proposed_mask",
    "sor_mask",
]


class DenoiseMethod(enum.StrEnum):
    PATTERN = "pattern"
    """Ours: sparse for its place in the scan pattern and seen edge-on (see `pattern_keep`)."""
    PROPOSED = "proposed"
    """The paper's Algorithm 1: threshold `H_g * C_r * D_n`, D_n from the observation centre."""
    FLOORED = "floored"
    """Algorithm 1 never stricter than SOR: `H_g * max(1, C_r * D_n)`."""
    SOR = "sor"
    """Statistical outlier removal: one threshold `H_g` for every point."""
    DSOR = "dsor"
    """Dynamic SOR: threshold `H_g * C_r * r_n`, r_n the range from the sensor."""
    RANGE_GAP = "range_gap"
    """Ranges between those of the neighbouring beams (see `range_gap`); its range noise and
    scan pattern come from the LiDAR (`range_noise_m`, the recording) or from the cloud."""


class DenoiseConfig(BaseModel):
    """Stage 1's parameters. `k`, `cs`, `cr` are the paper's (`k = 20`, `C_s = 0.01`,
    `C_r = 3.0`); `density_ratio`, `beam_cos`, `beam_extent` and `cell_deg` belong to `pattern`."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    enabled: bool = True
    method: DenoiseMethod = DenoiseMethod.PATTERN
    k: int = Field(default=20, ge=1, description="neighbours per point for the mean distance mu_n")
    cs: float = Field(default=0.01, description="C_s: global threshold H_g = mu + sigma * C_s")
    cr: float = Field(default=3.0, gt=0.0, description="C_r: dynamic threshold factor")
    density_ratio: float = Field(
        default=1.8, gt=0.0, description="pattern: mu_n over the expected spacing to be suspect"
    )
    beam_cos: float = Field(
        default=0.2, ge=0.0, le=1.0, description="pattern: |cos| beam vs local normal for edge-on"
    )
    beam_extent: float = Field(
        default=0.5,
        ge=0.0,
        description="pattern: spread along the beam over mu_n for a sheet (spinning: try 0.75)",
    )
    cell_deg: float = Field(
        default=10.0, gt=0.0, le=90.0, description="pattern: direction cell for the scan's spacing"
    )
    range_gap_k: int = Field(
        default=16, ge=4, description="range_gap: nearest directions a point is compared with"
    )
    range_noise_m: dict[str, float] = Field(
        default_factory=dict,
        description="range_gap: per LiDAR frame, its model's range-noise sigma (metres); frames "
        "not named have it estimated from each cloud",
    )
    floor_distance_m: float = Field(
        default=0.05, gt=0.0, description="RANSAC inlier distance of the floor fit (metres)"
    )
    floor_iterations: int = Field(default=200, ge=1, description="RANSAC hypotheses for the floor")
    population_points: int = Field(
        default=5000,
        ge=1,
        description="when only some points are judged (the pipeline judges those standing above "
        "the floor), the cloud-wide statistics (mu and sigma of mu_n; pattern's spacing per "
        "direction) come from this many random points of the whole cloud",
    )
    seed: int = Field(
        default=0, description="seed of the floor RANSAC and of the sample (results reproducible)"
    )
    optical_axis: tuple[float, float, float] = Field(
        default=(1.0, 0.0, 0.0),
        description="the centre of the LiDAR model's scan pattern in its own frame (Livox Mid-70: "
        "+x), for the observation centre of `proposed` and `floored`",
    )
    optical_axes: dict[str, tuple[float, float, float]] = Field(
        default_factory=dict,
        description="per LiDAR frame, where its model's optical axis differs from optical_axis",
    )
    filtered_patterns: tuple[ScanPattern, ...] = Field(
        default=(ScanPattern.NON_REPETITIVE,),
        description="the scan patterns whose clouds the pipeline filters (`repetitive` added: "
        "spinning LiDARs too, opt-in; see `pipeline.stages.denoise_stage.stage_1_filters`)",
    )
    scan_patterns: dict[str, ScanPattern] = Field(
        default_factory=dict,
        description="the pipeline filters the clouds of `filtered_patterns`; this maps a LiDAR "
        "frame to its scan pattern where the recording says otherwise (a spinning LiDAR whose "
        "driver publishes no ring field: repetitive)",
    )

    @field_validator("filtered_patterns")
    @classmethod
    def _known_patterns_only(cls, patterns: tuple[ScanPattern, ...]) -> tuple[ScanPattern, ...]:
        if ScanPattern.UNKNOWN in patterns:
            raise ValueError(
                "stage 1 never filters a LiDAR whose scan pattern is unknown (the filter would "
                "be a guess); name that LiDAR's pattern in denoise.scan_patterns instead"
            )
        return patterns


@dataclass(frozen=True)
class DenoiseResult:
    """What stage 1 did to one cloud.

    `keep`: (N,) bool, True = keep. `observation_centre`: (3,) in the LiDAR frame for the methods
    that use one, else None. `note`: why the cloud was left untouched when it was (disabled, too
    few points to judge); None when the filter ran. `seconds`: wall time of the call.
    `judged_points`: how many points were judged (all, unless the call named some).
    `parameters`: what `range_gap` used (range noise, scan pattern, whether each was estimated
    from the cloud); empty for the other methods.
    """

    keep: KeepMask
    method: DenoiseMethod
    seconds: float
    observation_centre: Points | None = None
    note: str | None = None
    judged_points: int = 0
    parameters: dict[str, float | str | bool] = field(default_factory=dict)

    @property
    def removed_points(self) -> int:
        return int(self.keep.size - np.count_nonzero(self.keep))


def denoise(
    points: ArrayLike,
    config: DenoiseConfig | None = None,
    optical_axis: Sequence[float] | ArrayLike | None = None,
    floor_plane: ArrayLike | None = None,
    judge: ArrayLike | None = None,
    *,
    range_noise_m: float | None = None,
    scan_pattern: ScanPattern | None = None,
) -> DenoiseResult:
    """Stage 1 on one LiDAR's accumulated cloud of one stop:

        result = denoise(stop.clouds[frame], config.denoise)
        cloud = stop.clouds[frame][result.keep]

    (the pipeline runs it through `pipeline.stages.denoise_stage.denoise_above_floor`, judging what
    stands above the floor).

    `points`: (N, 3) in the LiDAR frame (sensor at the origin). `optical_axis`: (3,) direction of
    the scan pattern's centre in that frame (default: `config.optical_axis`, Livox Mid-70: +x);
    only `proposed` and `floored` use it. `floor_plane`: optional (4,) `[a, b, c, d]`,
    `a x + b y + c z + d = 0` in the LiDAR frame, for the observation centre; fitted here when
    omitted. `judge`: optional (N,) bool, the points to judge (the others are kept): their
    neighbours are still searched among all points, and the cloud-wide statistics come from
    `population_points` random points of the whole cloud. The pipeline judges only what stands
    above the floor, where the objects are: a tenth of a full-rate cloud, a tenth of the time.
    `range_noise_m`, `scan_pattern`: the LiDAR's, for `range_gap` (estimated from the cloud when
    None; `parameters` of the result says what was used).

    Defined results rather than errors: a cloud of at most `k` points is kept whole (there are
    not `k` neighbours to judge density by) and `note` says so; duplicated points and a cloud
    collapsed to one spot have zero neighbour distances and are kept. Non-finite coordinates or
    a wrong shape raise `BadInputError`.
    """
    cfg = config if config is not None else DenoiseConfig()
    start = time.perf_counter()
    cloud = as_cloud(points)
    if not cfg.enabled:
        return _untouched(cloud, cfg, start, "stage 1 disabled in the config")
    k = cfg.range_gap_k if cfg.method is DenoiseMethod.RANGE_GAP else cfg.k
    if len(cloud) <= k:
        return _untouched(
            cloud, cfg, start, f"{len(cloud)} points are too few to judge with k={k}; kept all"
        )
    rows, sample = (None, None) if judge is None else _judged_rows(cloud, cfg, judge)
    parameters: dict[str, float | str | bool] = {}
    centre: Points | None = None
    if cfg.method is DenoiseMethod.RANGE_GAP:
        judged, report = range_gap_keep(
            cloud,
            RangeGapSettings(k=cfg.range_gap_k),
            range_noise_m=range_noise_m,
            pattern=scan_pattern,
            rows=rows,
            population=sample,
            floor_plane=None if floor_plane is None else _unit_plane(floor_plane),
        )
        parameters = report.as_details()
    else:
        judged, centre = _density_keep(cloud, cfg, optical_axis, floor_plane, judge)
    keep = judged
    if rows is not None:
        keep = np.ones(len(cloud), dtype=np.bool_)
        keep[rows] = judged
    judged_points = len(cloud) if rows is None else len(rows)
    seconds = time.perf_counter() - start
    return DenoiseResult(keep, cfg.method, seconds, centre, None, judged_points, parameters)


def _density_keep(
    cloud: Points,
    cfg: DenoiseConfig,
    optical_axis: Sequence[float] | ArrayLike | None,
    floor_plane: ArrayLike | None,
    judge: ArrayLike | None,
) -> tuple[KeepMask, Points | None]:
    """The methods built on the mean distance `mu_n` to the `k` nearest points: the keep mask of
    the judged points, and the observation centre where the method uses one."""
    # Every point judged: one kNN query over the cloud. Some judged: a query for them and for a
    # random sample of the cloud, which gives the cloud-wide statistics (`population`).
    rows: NDArray[np.intp] | None = None
    population: tuple[NDArray[np.float64], NDArray[np.intp]] | None = None
    if judge is None:
        neighbours, points = nearest_neighbours(cloud, cfg.k), cloud
    else:
        rows, sample_rows = _judged_rows(cloud, cfg, judge)
        queried = np.union1d(rows, sample_rows)
        found = nearest_neighbours(cloud, cfg.k, queried)
        at = np.searchsorted(queried, rows)
        neighbours = Neighbours(found.mean_distance[at], found.index[at])
        population = (found.mean_distance[np.searchsorted(queried, sample_rows)], sample_rows)
        points = cloud[rows]
    mu = neighbours.mean_distance
    sample = None if population is None else population[0]
    if cfg.method is DenoiseMethod.PATTERN:
        keep = pattern_keep(
            neighbours,
            cloud,
            density_ratio=cfg.density_ratio,
            beam_cos=cfg.beam_cos,
            beam_extent=cfg.beam_extent,
            cell_deg=cfg.cell_deg,
            rows=rows,
            population=population,
        )
        return keep, None
    if cfg.method is DenoiseMethod.SOR:
        return sor_keep(mu, cfg.cs, sample), None
    if cfg.method is DenoiseMethod.DSOR:
        return dsor_keep(mu, points, cfg.cs, cfg.cr, sample), None
    centre = observation_centre(
        cloud,
        cfg.optical_axis if optical_axis is None else optical_axis,
        floor_plane,
        floor_distance_m=cfg.floor_distance_m,
        floor_iterations=cfg.floor_iterations,
        seed=cfg.seed,
    )
    floored = cfg.method is DenoiseMethod.FLOORED
    keep = proposed_keep(mu, points, centre, cfg.cs, cfg.cr, floored=floored, population=sample)
    return keep, centre


def _judged_rows(
    cloud: Points, cfg: DenoiseConfig, judge: ArrayLike
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Rows to judge, and the random rows the cloud-wide statistics come from."""
    mask = np.asarray(judge, dtype=np.bool_).reshape(-1)
    if mask.shape != (len(cloud),):
        raise BadInputError(
            f"the judge mask must have one entry per point ({len(cloud)}); got {mask.shape[0]}"
        )
    size = min(cfg.population_points, len(cloud))
    sample = np.random.default_rng(cfg.seed).choice(len(cloud), size=size, replace=False)
    return np.flatnonzero(mask), np.sort(sample)


def _unit_plane(plane: ArrayLike) -> NDArray[np.float64]:
    """`[a, b, c, d]` scaled so that `(a, b, c)` is a unit normal (distances in metres)."""
    values = np.asarray(plane, dtype=np.float64).reshape(4)
    norm = float(np.linalg.norm(values[:3]))
    if not np.isfinite(values).all() or norm < 1e-12:
        raise BadInputError("the floor plane must be a finite [a, b, c, d] with a non-zero normal")
    return np.asarray(values / norm, dtype=np.float64)


def _untouched(cloud: Points, cfg: DenoiseConfig, start: float, note: str) -> DenoiseResult:
    keep = np.ones(len(cloud), dtype=np.bool_)
    return DenoiseResult(keep, cfg.method, time.perf_counter() - start, None, note)
