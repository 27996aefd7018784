"""A LiDAR's scan pattern from its PointCloud2s: the beam-index field its driver publishes, or,
without one, whether the directions it fires recur scan after scan.

A repetitive scanner (spinning multi-beam, raster) re-fires the same directions every scan; a
non-repetitive one (Livox rosette) keeps filling in new ones. Directions are taken in the LiDAR's
own frame, so a moving base does not change them.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

# scipy's single-threaded tree, not pykdtree: judging a sparse Mid-70 (200 points a scan) on
# the loaded 2-core dev machine took pykdtree 0.50 s with its default OpenMP threads (0.07 s
# pinned to one, which a library cannot do per call), scipy's 0.11 s.
from scipy.spatial import cKDTree as KDTree

from pipeline.problem import ScanPattern

BEAM_INDEX_FIELDS = ("ring", "channel", "laser_id")
"""The per-point beam index of repetitive scanners' drivers: `ring` (velodyne, ouster, hesai,
rslidar), `channel` (Autoware nebula: Velodyne, Hesai, Robosense), `laser_id` (Luminar)."""
NON_REPETITIVE_FIELDS = ("line", "tag")
"""Livox drivers' per-point laser line and return tag: a non-repetitive scanner."""

# Judged from the points: the first scans with enough points, the earlier ones as the reference
# and the later ones queried against it (a scan is compared with scans before it, not itself).
REFERENCE_SCANS = 8
QUERY_SCANS = 4
MIN_SCANS = 4
MIN_POINTS_PER_SCAN = 100
MAX_SKIPPED = 100
# A union of more points costs more to index than it tells (dense scans need two references).
MAX_REFERENCE_POINTS = 100_000
QUERY_SAMPLE = 1000
# The chance baseline: the queries moved by this many times one scan's own point spacing.
CHANCE_STEP = 1.5
# The local spacing that distances are measured in: the k-th nearest reference direction, with
# k this many per reference scan (a union holds a repetitive scanner's directions once a scan).
LOCAL_SCALE_NEIGHBOURS = 4
# Recurrence: the query scans' distance to the reference over chance's (both in local spacing).
# Measured on the synthesiser's models (tests/pipeline/io/test_scan_pattern.py holds the
# cases): spinning 16-64 beams, exact or free-running azimuths, half the returns missing,
# floor-only returns: 0.00-0.22; 16 beams at a tenth of the rate with 30 % of the returns (750
# points a scan): 0.38, at a twentieth (350 points): 0.67 (unknown); Mid-70 rosettes of 200 to
# 10,000 points a scan: 0.96-1.19 (a rosette avoids where it just fired); random floor points,
# 255 a scan: 0.86. In between, the pattern stays unknown.
REPETITIVE_BELOW = 0.5
NON_REPETITIVE_ABOVE = 0.8


@dataclass(frozen=True)
class PatternJudgement:
    """A LiDAR's scan pattern and what it rests on (`basis`, said to the user as it is)."""

    pattern: ScanPattern
    basis: str
    recurrence: float | None = None


def pattern_from_fields(names: Iterable[str]) -> PatternJudgement | None:
    """The pattern a PointCloud2's field names tell, or None when they tell nothing.

    Livox's `line`/`tag` win over a beam index: no repetitive scanner's driver publishes them.
    """
    present = set(names)
    livox = [name for name in NON_REPETITIVE_FIELDS if name in present]
    if livox:
        return PatternJudgement(ScanPattern.NON_REPETITIVE, f"{livox[0]!r} field (Livox)")
    beams = [name for name in BEAM_INDEX_FIELDS if name in present]
    if beams:
        return PatternJudgement(ScanPattern.REPETITIVE, f"{beams[0]!r} field (beam index)")
    return None


class DirectionRecurrence:
    """Collects a LiDAR's first scans (points in its frame) and judges whether directions recur.

    Each query scan's directions are compared with the reference scans': the distance to the
    nearest reference direction, in units of the local spacing of the reference (its k-th
    nearest), against the same for the queries moved aside by chance (a step of one scan's
    spacing). A repetitive scanner hits its own directions again, far nearer than chance, even
    with a free-running azimuth (the reference's scans then cover each beam's line densely) or
    missing returns. A non-repetitive one lands no nearer than chance. A ratio, not an angle:
    the test holds for sparse and dense clouds alike.
    """

    def __init__(self, *, seed: int = 0) -> None:
        self._scans: list[NDArray[np.float32]] = []
        self._seed = seed
        self.skipped = 0
        """Scans with too few points to judge by (a LiDAR facing the sky, starting up)."""

    @property
    def wants_more(self) -> bool:
        # A LiDAR that never sees enough is not decoded scan after scan through the recording.
        return len(self._scans) < REFERENCE_SCANS + QUERY_SCANS and self.skipped < MAX_SKIPPED

    def add(self, points: NDArray[np.floating[Any]]) -> None:
        """One scan's valid points, (N, 3) in the LiDAR frame (no NaN, none at the origin)."""
        if not self.wants_more:
            return
        if len(points) < MIN_POINTS_PER_SCAN:
            self.skipped += 1
            return
        directions = np.asarray(points, dtype=np.float32)
        norms = np.linalg.norm(directions, axis=1, keepdims=True)
        self._scans.append(directions[norms[:, 0] > 0] / norms[norms[:, 0] > 0])

    def judge(self) -> PatternJudgement:
        """The pattern, or UNKNOWN with the reason (too few scans, or a recurrence in between)."""
        scans = self._scans
        if len(scans) < MIN_SCANS:
            return PatternJudgement(
                ScanPattern.UNKNOWN,
                f"no beam-index field, and only {len(scans)} scans with "
                f"{MIN_POINTS_PER_SCAN} or more valid points to judge its points by "
                f"({MIN_SCANS} needed; {self.skipped} sparser ones seen)",
            )
        queries = min(QUERY_SCANS, len(scans) // 2)
        reference = _reference(scans[:-queries])
        recurrence = _recurrence(reference, scans[-queries:], np.random.default_rng(self._seed))
        said = (
            f"no beam-index field; judged from {len(scans)} scans: their directions recur at "
            f"{recurrence:.2f} of chance distance"
        )
        if recurrence < REPETITIVE_BELOW:
            return PatternJudgement(ScanPattern.REPETITIVE, said, recurrence)
        if recurrence > NON_REPETITIVE_ABOVE:
            return PatternJudgement(ScanPattern.NON_REPETITIVE, said, recurrence)
        return PatternJudgement(
            ScanPattern.UNKNOWN,
            f"{said}, between repetitive (< {REPETITIVE_BELOW}) and non-repetitive "
            f"(> {NON_REPETITIVE_ABOVE})",
            recurrence,
        )


def _reference(scans: list[NDArray[np.float32]]) -> list[NDArray[np.float32]]:
    """As many leading scans as the point budget allows (at least two)."""
    kept: list[NDArray[np.float32]] = []
    total = 0
    for scan in scans:
        if len(kept) >= 2 and total + len(scan) > MAX_REFERENCE_POINTS:
            break
        kept.append(scan)
        total += len(scan)
    return kept


def _recurrence(
    reference_scans: list[NDArray[np.float32]],
    queries: list[NDArray[np.float32]],
    rng: np.random.Generator,
) -> float:
    reference = np.concatenate(reference_scans)
    tree = KDTree(reference)
    # One scan's own spacing (a union may hold a repetitive scanner's directions many times).
    first = reference_scans[0]
    own = KDTree(first).query(_sample(first, rng), k=2)[0][:, 1]
    step = CHANCE_STEP * float(np.median(own))
    scale_k = LOCAL_SCALE_NEIGHBOURS * len(reference_scans)
    ratios = []
    for scan in queries:
        sample = _sample(scan, rng)
        near = _relative_distance(tree, sample, scale_k)
        chance = np.median(
            [_relative_distance(tree, _displaced(sample, step, rng), scale_k) for _ in range(2)]
        )
        ratios.append(near / chance if chance > 0 else 1.0)
    return float(np.median(ratios))


def _relative_distance(tree: KDTree, directions: NDArray[np.float32], k: int) -> float:
    """Median over `directions` of the distance to the nearest reference direction, in units of
    the distance to the k-th nearest: the reference's local spacing, so that a cloud's density
    (floor points crowding at the horizon) does not weigh in."""
    distances = tree.query(directions, k=k)[0]
    nearest, scale = distances[:, 0], distances[:, -1]
    usable = scale > 0
    return float(np.median(nearest[usable] / scale[usable])) if usable.any() else 0.0


def _sample(directions: NDArray[np.float32], rng: np.random.Generator) -> NDArray[np.float32]:
    if len(directions) <= QUERY_SAMPLE:
        return directions
    return directions[rng.choice(len(directions), QUERY_SAMPLE, replace=False)]


def _displaced(
    directions: NDArray[np.float32], angle: float, rng: np.random.Generator
) -> NDArray[np.float32]:
    """Each direction moved by `angle` (radians) towards a random side: points placed by chance
    at the same density. (Not one rotation of all: that shifts a cloud's density gradients, e.g.
    a floor's points crowding at the horizon, coherently and biases the baseline.)"""
    side = rng.normal(size=directions.shape).astype(np.float32)
    side -= np.sum(side * directions, axis=1, keepdims=True) * directions
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    moved: NDArray[np.float32] = directions + np.float32(np.tan(angle)) * side
    moved /= np.linalg.norm(moved, axis=1, keepdims=True)
    return moved
