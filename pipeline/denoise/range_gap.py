"""The range-gap filter: a mixed return's range is not one its neighbouring beams see.

A bleeding point is a range reported *between* two surfaces that one beam straddled. Seen from
the sensor, its neighbouring beams (the nearest directions, whatever the scan pattern) return
from the near surface or the far one, rarely from where it is. So a point is noise when, among
its `k` nearest directions,

1. few return within `tau` of its own range (`support <= support_share * k`),
2. some return nearer than its range minus `tau` and some farther than its range plus `tau`
   (`min(nearer, farther) >= side_share * k`: it lies between two surfaces), and
3. no smooth surface through it fits its neighbours' ranges within `tau`
   (`slope.on_smooth_surface`: a surface seen at grazing incidence also has neighbours nearer
   and farther, but on a plane with the point; a mixed return's neighbours are a step).

A candidate is kept when a neighbour within `tau` of its range is itself well supported (a
slanted surface or a silhouette leaves a point few neighbours at its range, but those continue
into points with many), and when it lies within three range-noise sigmas of the floor plane in
3D (issue 19's definition of a bleeding point: farther than that from every surface; a mixed
return between an object's foot and the floor often is not).

A repetitive scan (a spinning LiDAR) is judged instead by `repeats.pure_support_keep`: support
only from distinct directions whose repeats agree within the noise (a mixed return repeats at one
level scan after scan and would support itself here).

The parameters come from the LiDAR and the cloud, not from one simulator's tuning: `tau` is the
range-noise sigma times the two-sided Gaussian quantile of `false_alarm_rate` (3.9 sigmas for
1e-4: the share of clean points that noise alone may push that far), the sigma from the LiDAR
model when the config gives it, else estimated from the cloud (the spread of range differences
between beams that point the same way); the scan pattern (given, or estimated: a spinning LiDAR
fires the same directions every scan, so a stop cloud holds exact repeats of each direction)
picks the repetitive test above. The beam divergence needs no parameter: the tests look at
ranges, not at how far from an edge a point lies, so any width of the smeared band is handled
as long as the `k` neighbouring directions reach across it.

One kNN query on unit directions (float32), then vectorised counts: about the cost of SOR's query.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.denoise.centre import fit_floor_plane
from pipeline.denoise.filters import KeepMask, Points
from pipeline.denoise.repeats import group_directions, has_repeats, pure_support_keep
from pipeline.denoise.slope import on_smooth_surface
from pipeline.problem import ScanPattern

# Directions closer than this (radians) are the same beam fired again (float32 unit vectors
# resolve ~1e-7; a rosette's neighbours are 1e-3 apart).
_REPEAT_RAD = 1e-5
# A cloud whose points mostly have a repeat of their direction among their neighbours: repetitive.
_REPEAT_SHARE = 0.5
# |difference| of two draws of N(0, s^2): median 0.6745 * sqrt(2) * s.
_MEDIAN_ABS_DIFF = 0.6745 * math.sqrt(2.0)


@dataclass(frozen=True)
class RangeGapSettings:
    """The filter's parameters that do not depend on the LiDAR (see the module docstring)."""

    k: int = 16
    false_alarm_rate: float = 1e-4
    """Share of clean points whose range noise alone may carry them `tau` away from their
    surface: `tau` is the two-sided Gaussian quantile of this rate in range-noise sigmas (3.9
    for 1e-4: a few false alarms in a 145k-point stop cloud; 3 sigmas gave hundreds)."""
    surface_margin_sigmas: float = 3.0
    """A candidate within this many range-noise sigmas of the floor plane (in 3D) is kept: issue
    19's definition of a bleeding point (farther than three sigmas from every surface)."""
    purity_iqr_sigmas: float = 4.0
    """Repetitive scans: a direction is pure (sees one surface) when the interquartile range of
    its repeats is at most this many sigmas (a Gaussian's is 1.35: room for a few returns)."""
    support_share: float = 0.25
    side_share: float = 0.125

    @property
    def tau_sigmas(self) -> float:
        """`tau` in range-noise sigmas, from `false_alarm_rate`."""
        return NormalDist().inv_cdf(1.0 - self.false_alarm_rate / 2.0)


@dataclass(frozen=True)
class RangeGapReport:
    """What the filter used on one cloud: the range noise (m), the scan pattern, and which of the
    two came from the cloud itself rather than the config."""

    range_noise_m: float
    pattern: ScanPattern
    noise_estimated: bool
    pattern_estimated: bool

    def as_details(self) -> dict[str, float | str | bool]:
        return {
            "range_noise_m": round(self.range_noise_m, 5),
            "scan_pattern": str(self.pattern),
            "range_noise_estimated": self.noise_estimated,
            "scan_pattern_estimated": self.pattern_estimated,
        }


@dataclass(frozen=True)
class _Beams:
    """Per judged point: range (N,), unit direction (N, 3), and its `k` nearest directions'
    range differences (N, k), angles (N, k) and rows in the cloud (N, k) (itself excluded)."""

    ranges: NDArray[np.float64]
    units: Points
    range_diff: NDArray[np.float64]
    angle: NDArray[np.float64]
    index: NDArray[np.intp]


def range_gap_keep(
    cloud: Points,
    settings: RangeGapSettings = RangeGapSettings(),
    *,
    range_noise_m: float | None = None,
    pattern: ScanPattern | None = None,
    rows: NDArray[np.intp] | None = None,
    population: NDArray[np.intp] | None = None,
    floor_plane: NDArray[np.float64] | None = None,
) -> tuple[KeepMask, RangeGapReport]:
    """Keep mask of the points `rows` of `cloud` (N, 3, sensor at the origin; all when None),
    and what it used. `range_noise_m` / `pattern`: the LiDAR's, when known; estimated from the
    cloud when None (or `pattern` UNKNOWN). `population`: the rows (e.g. a random sample of the
    whole cloud) that the estimates come from when only some points are judged; default: the
    judged points. `floor_plane`: `[a, b, c, d]` (unit
    normal, LiDAR frame), the cloud's floor; fitted here (its largest plane) when None. The
    cloud needs more than `settings.k` points."""
    sky = _directions(cloud)
    beams = _beams(sky, settings.k, rows)
    measured = beams if population is None else _beams(sky, settings.k, population)
    noise_estimated = range_noise_m is None
    sigma = estimate_range_noise(measured) if range_noise_m is None else range_noise_m
    pattern_estimated = pattern is None or pattern is ScanPattern.UNKNOWN
    if pattern is None or pattern is ScanPattern.UNKNOWN:
        pattern = estimate_scan_pattern(measured)
    report = RangeGapReport(sigma, pattern, noise_estimated, pattern_estimated)
    if sigma <= 0.0:
        return np.ones(len(beams.ranges), dtype=np.bool_), report
    tau = settings.tau_sigmas * sigma
    noise: NDArray[np.bool_] | None = None
    if pattern is ScanPattern.REPETITIVE:
        groups = group_directions(cloud)
        if has_repeats(groups):
            pure_iqr = settings.purity_iqr_sigmas * sigma
            noise = ~pure_support_keep(
                cloud, groups, k=settings.k, tau_m=tau, pure_iqr_m=pure_iqr, rows=rows
            )
    if noise is None:
        noise = ~_gap_keep(sky, beams, settings, tau)
        noise = _well_supported(sky, beams, noise, settings.k, tau, settings.support_share)
    own = np.arange(len(cloud)) if rows is None else rows
    margin = settings.surface_margin_sigmas * sigma
    return ~_off_the_floor(cloud, own, noise, floor_plane, tau, margin), report


def _gap_keep(sky: _Directions, beams: _Beams, settings: RangeGapSettings, tau: float) -> KeepMask:
    """The generic test of the module docstring on the judged `beams`: few neighbours at the
    point's range, some on either side, and not on a smooth surface through them."""
    k = settings.k
    diff = beams.range_diff
    support = np.count_nonzero(np.abs(diff) <= tau, axis=1)
    sides = np.minimum(np.count_nonzero(diff < -tau, axis=1), np.count_nonzero(diff > tau, axis=1))
    candidates = np.flatnonzero(
        (support <= settings.support_share * k) & (sides >= settings.side_share * k)
    )
    smooth = on_smooth_surface(
        beams.units[candidates],
        sky.units[beams.index[candidates]],
        diff[candidates],
        tau,
    )
    keep = np.ones(len(diff), dtype=np.bool_)
    keep[candidates[~smooth]] = False
    return keep


def _well_supported(
    sky: _Directions,
    beams: _Beams,
    noise: NDArray[np.bool_],
    k: int,
    tau: float,
    support_share: float,
) -> NDArray[np.bool_]:
    """`noise` less the points with a neighbour within `tau` of their range that is itself well
    supported (more than `support_share * k` of its neighbours within `tau`).

    A surface seen at a slant, or near its own silhouette, leaves a point few neighbours at its
    range; but those few continue the surface into points that have many. A mixed return's
    neighbours at its range, where it has any, are mixed returns too, as poorly supported."""
    candidates = np.flatnonzero(noise)
    if len(candidates) == 0:
        return noise
    near = np.abs(beams.range_diff[candidates]) <= tau
    rows, inverse = np.unique(beams.index[candidates], return_inverse=True)
    neighbours = _beams(sky, k, rows)
    support = np.count_nonzero(np.abs(neighbours.range_diff) <= tau, axis=1)
    strong = support[inverse.reshape(near.shape)] > support_share * k
    rescued = (near & strong).any(axis=1)
    out = noise.copy()
    out[candidates[rescued]] = False
    return out


def _off_the_floor(
    cloud: Points,
    own: NDArray[np.intp],
    noise: NDArray[np.bool_],
    floor_plane: NDArray[np.float64] | None,
    tau: float,
    margin: float,
) -> NDArray[np.bool_]:
    """`noise` (over the rows `own` of `cloud`) less the points within `margin` (metres) of the
    floor plane.

    A mixed return between an object's foot and the floor lies off both along the beam, but
    in 3D it may sit within the noise of the floor, where it harms nothing: issue 19 calls a
    return bleeding only when it is farther than three range-noise sigmas from every surface.
    Only the candidates are tested, so the margin is that definition, not a false-alarm quantile.
    The floor is fitted (RANSAC, inliers within `tau`) when not given."""
    candidates = np.flatnonzero(noise)
    if len(candidates) == 0:
        return noise
    plane = fit_floor_plane(cloud, distance_m=tau) if floor_plane is None else floor_plane
    if plane is None:
        return noise
    points = cloud[own[candidates]]
    near = np.abs(points @ plane[:3] + plane[3]) <= margin
    out = noise.copy()
    out[candidates[near]] = False
    return out


def estimate_range_noise(beams: _Beams) -> float:
    """Range-noise sigma (m) from the cloud: the median |range difference| between each point and
    the nearest of its neighbouring directions in range, over the points whose nearest direction
    is closest (a tenth of the cloud: facing surfaces, densely sampled, where slope adds least),
    rescaled as for two Gaussian draws. Overestimates a little where surfaces slope."""
    nearest = np.argmin(beams.angle, axis=1)
    rows = np.arange(len(nearest))
    gap = np.abs(beams.range_diff[rows, nearest])
    angle = beams.angle[rows, nearest]
    closest = angle <= np.quantile(angle, 0.1)
    return float(np.median(gap[closest]) / _MEDIAN_ABS_DIFF)


def estimate_scan_pattern(beams: _Beams) -> ScanPattern:
    """REPETITIVE when most points have an exact repeat of their direction among their
    neighbours (a spinning LiDAR's stop cloud: one point per beam and scan), else
    NON_REPETITIVE."""
    repeated = np.any(beams.angle < _REPEAT_RAD, axis=1)
    share = float(np.mean(repeated)) if len(repeated) else 0.0
    return ScanPattern.REPETITIVE if share >= _REPEAT_SHARE else ScanPattern.NON_REPETITIVE


@dataclass(frozen=True)
class _Directions:
    """The whole cloud as seen from the sensor: `ranges` (N,) metres, `units` (N, 3) unit
    directions in the LiDAR frame, and a kd-tree over them (float32) for the kNN queries."""

    ranges: NDArray[np.float64]
    units: Points
    tree: Any


def _directions(cloud: Points) -> _Directions:
    from pykdtree.kdtree import KDTree

    ranges = np.linalg.norm(cloud, axis=1)
    units = cloud / np.where(ranges > 0.0, ranges, 1.0)[:, None]
    tree = KDTree(np.ascontiguousarray(units, dtype=np.float32), leafsize=32)
    return _Directions(ranges, units, tree)


def _beams(sky: _Directions, k: int, rows: NDArray[np.intp] | None) -> _Beams:
    """The `k` nearest directions of the points `rows` (all when None), themselves excluded."""
    own = np.arange(len(sky.ranges)) if rows is None else rows
    query = np.ascontiguousarray(sky.units[own], dtype=np.float32)
    chord, index = sky.tree.query(query, k=k + 1)
    # Repeated directions tie at distance 0, so the point itself need not come first: drop it
    # wherever it is (else the farthest neighbour).
    is_self = index == own[:, None]
    drop = np.where(is_self.any(axis=1), np.argmax(is_self, axis=1), k)
    keep = np.ones(index.shape, dtype=np.bool_)
    keep[np.arange(len(own)), drop] = False
    index = index[keep].reshape(len(own), k).astype(np.intp)
    chord = chord[keep].reshape(len(own), k).astype(np.float64)
    ranges = sky.ranges[own]
    return _Beams(
        ranges=ranges,
        units=sky.units[own],
        range_diff=sky.ranges[index] - ranges[:, None],
        angle=2.0 * np.arcsin(np.clip(chord / 2.0, 0.0, 1.0)),
        index=index,
    )
