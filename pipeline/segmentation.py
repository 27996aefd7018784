"""Stage 2: split one accumulated LiDAR cloud into its floor plane and its object points.

Floor: RANSAC plane among planes tilted at most `max_floor_tilt_deg` from the expected up
direction, drawn from the cloud's lower envelope and scored against the points below it, refined
by least squares on its inliers. Objects: the points clearly above the floor,
grouped by Euclidean clustering (radius graph, connected components); small clusters are dropped.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field
from pykdtree.kdtree import KDTree
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from pipeline.downsample import voxel_downsample
from pipeline.geometry import Plane, pack_cells, tangent_basis, voxel_keys
from pipeline.surface_bias import range_noise_from_smoothing, smoothing_offsets
from pipeline.surfaces import LocalSurfaces, local_surfaces
from pipeline.transforms import Points

_FROZEN = ConfigDict(frozen=True, extra="forbid")


SurfaceModel = Literal["plane", "quadric", "beam_quadric", "beam_fit"]
"""The local surfaces object points are projected onto (`SegmentationConfig.surface_model`)."""


class SegmentationConfig(BaseModel):
    """Floor RANSAC and Euclidean clustering; lengths in metres."""

    model_config = _FROZEN

    floor_distance_m: float = Field(
        default=0.02, gt=0, description="RANSAC inlier band around the floor"
    )
    voxel_size_m: float = Field(
        default=0.02,
        ge=0,
        description="object candidates are reduced to one point (the centroid) per voxel of this "
        "edge, which also averages their range noise; 0 keeps every point",
    )
    floor_fit_points: int | None = Field(
        default=20_000, ge=3, description="the floor's least-squares refit uses this many inliers"
    )
    floor_fit: Literal["along_beams", "points"] = Field(
        default="along_beams",
        description="how the floor's final refit weighs each inlier: along_beams (the default) "
        "takes the range noise to lie along each point's beam (`fit_plane_along_beams`), "
        "points treats the points as exact (total least squares, `fit_plane`), which tilts the "
        "floor of a LiDAR that meets it obliquely from one side: 0.076 deg at every stop on "
        "bench_random seed 1066, whose other LiDARs all ended 0.07 deg off in roll against it "
        "(along the beams 0.016 deg; over seeds 1000-1099 92/100 within 5 mm / 0.1 deg either "
        "way, see docs/method.md)",
    )
    ransac_iterations: int = Field(
        default=1000,
        ge=1,
        description="planes drawn through three of the lowest points (see floor_cell_m); where "
        "walls and shelves hide most of the floor, a sixth of those columns may be floor, and "
        "1000 draws hold three of them with 99 % odds (100 draws: 37 %)",
    )
    ransac_scored_points: int = Field(
        default=2000,
        ge=10,
        description="hypotheses are scored on this many random points of the cloud",
    )
    max_floor_tilt_deg: float = Field(
        default=30.0,
        gt=0,
        le=90,
        description="floor normal vs the up direction of the initial extrinsics",
    )
    floor_cell_m: float = Field(
        default=0.25,
        gt=0,
        description="the floor's hypotheses are drawn from the lowest point of each column of "
        "this width across the expected up: walls and shelves can fill most of a room's cloud, "
        "but the bottom of each column is floor or stands on it",
    )
    floor_envelope_points: int = Field(
        default=20_000, ge=3, description="the lowest points are taken among this many random ones"
    )
    min_floor_points: int = Field(
        default=200, ge=3, description="fewer inliers: no floor in this cloud"
    )
    object_min_height_m: float = Field(
        default=0.06,
        ge=0,
        description="object points lie at least this far above the floor plane; lower, the floor's "
        "range noise grows skirts round the objects that differ from one viewpoint to the next",
    )
    cluster_radius_m: float = Field(
        default=0.06, gt=0, description="Euclidean clustering tolerance"
    )
    min_cluster_points: int = Field(
        default=30, ge=1, description="smaller clusters are dropped as noise"
    )
    surface_neighbours: int = Field(
        default=80,
        ge=3,
        description="neighbours whose surface gives an object point's normal and smoothed "
        "position. Objects are voxelised at 2 cm and seen with 2-3 cm of range noise: a patch "
        "of 30 is about as deep as it is wide and its normal nearly arbitrary (median 28 deg off "
        "on a plane 45 deg to the beams), which biased whole recordings (bench_random seed 1013 "
        "10.4 mm, passed). 80, measured against 30 (tests/bench/bench_random.py and "
        "bench_calibration.py, method surface_k30): seeds 1000-1019 at full rate 16/20 within "
        "5 mm / 0.1 deg against 11/20, max 7.2 against 14.2 mm, no false pass against one; at "
        "0.2 of the rate (seeds 1000-1011) 10/12 against 8/12; the paper protocol's eight cases "
        "(5 seeds each) 2.44 against 2.33 mm mean, every case within 3.9 mm and 0.05 deg "
        "(set1-box 2.69 against 1.93 and set2-box 2.46 against 2.03 worse, driven 3.61 against "
        "3.91 and set1-capsule 1.54 against 2.05 better); a trial takes 15-30 % longer",
    )
    surface_passes: int = Field(
        default=1,
        ge=1,
        description="projections of the object points onto their local surfaces, each from "
        "where the last left them over the same neighbours (`local_planes`): one pass leaves "
        "a sheet several millimetres thick under heavy range noise, whose positions and "
        "normals move the cost's minimum off the truth (seed 1060). Opt-in: over bench_random "
        "seeds 1040-1089 four passes remove the false pass (seed 1060, 10.1 -> 4.6 mm) and "
        "help mixed and spinning sensors, but hurt the rosettes' figure-eights (+0.6 mm) and "
        "cost 15-48 % more time (docs/method.md)",
    )
    surface_centre_neighbours: int | None = Field(
        default=10,
        ge=1,
        description="the local plane passes through the centroid of this many nearest points "
        "(fewer than surface_neighbours flattens curved objects less); None: all of them",
    )
    min_incidence_cos: float = Field(
        default=0.12,
        ge=0,
        lt=1,
        description="object points whose surface the beam meets more edge-on than this (|cos| of "
        "beam vs normal) are dropped: bleeding points trail behind edges as sheets that contain "
        "the beam",
    )
    smooth_objects: bool = Field(
        default=True, description="object points are projected onto their local plane (range noise)"
    )
    surface_model: SurfaceModel = Field(
        default="beam_quadric",
        description="the local surface object points are projected onto and take normals "
        "from: a plane flattens curved objects by a few millimetres over a patch (biased with "
        "the view, 6 mm on full-rate cylinders); a quadric follows them. Under 30 mm of range "
        "noise the quadric, fitted along its patch's normal, settles the points 3-5 mm behind "
        "the true surfaces along their beams (tests/bench/bench_surface_bias.py); the beam "
        "quadric (the default) fits the same patch along each point's beam and moves the point "
        "along it (the normal stays the quadric's), and its smoothed points lie within ~1 mm "
        "of the true surfaces on average. Over bench_random seeds 1000-1099 at full rate "
        "(80-point patches) it succeeds on 89 of 100 against the quadric's 87, with no false "
        "pass against one, median 1.22 against 1.86 mm, but six false fails against four and a "
        "few thousandths of a degree worse on rosettes turning in place (docs/method.md). "
        "beam_fit (opt-in, experimental) is beam_quadric with each normal from the plane "
        "fitted along the point's beam (C^-1 b, not tilted by range noise; `local_planes`): on "
        "2 cm voxels under 2 cm of noise its normals are far closer to the surface's (median "
        "7.7 against 28 deg, tests/pipeline/test_surfaces.py) and it takes seed 1013 from 10.4 "
        "to 1.4 mm, but ambiguous patches lean their normals on the beams: seeds 1000, 1006, "
        "1010, 1015 and 1017 pass 11-21 mm off (five false passes over 1000-1019, against one "
        "with the quadric; 30-point patches) and set1-box seeds 0-4 end 9.5-17.7 mm off "
        "(1.7-2.4 with the quadric)",
    )
    surface_patch: Literal["fixed", "noise"] = Field(
        default="fixed",
        description="fixed: every patch has surface_neighbours points. noise (opt-in): "
        "surface_neighbours is the patch at the reference range noise and point spacing (2 cm "
        "each: a Mid-70 seen densely, voxelised at 2 cm), and each cloud's patch scales as its "
        "own range noise over its point spacing (both measured on the cloud, "
        "`patch_neighbours`), which keeps the tilt that noise gives a patch's normal the same: "
        "noisier LiDARs get larger patches, sparse clouds smaller ones (a fixed count spans a "
        "wider, more curved piece of surface there). Opt-in: with today's other defaults, over "
        "88 of bench_random's seeds 1000-1099, 83/88 within 5 mm / 0.1 deg against 81, no false "
        "pass, but false fails 5 against 3, two lanes lost, the driven routine of the paper "
        "protocol 4.28 mm against 3.11 (over its 3.9 mm), and up to twice the seconds "
        "(docs/method.md)",
    )
    surface_debias: Literal["none", "bootstrap"] = Field(
        default="none",
        description="bootstrap: the offset at which the surface fit settles noisy points off "
        "the surface they sample is measured on each cloud (the fit run again on the smoothed "
        "points with the range noise it removed added back, both signs; "
        "`pipeline.surface_bias`) and taken back. On seed 1060's 64-beam LiDAR under 30 mm of "
        "range noise it takes the smoothed surfaces from 7.0 to 4.0 mm behind the true ones "
        "along the beams (the Mid-360 beside it from 4.1 to -0.6 mm), and one cylinder under "
        "30 mm from 7.7 to -0.8 mm. Opt-in: on eight hard recordings it moved seven closer to "
        "the truth and one further, but over bench_random seeds 1040-1059 it succeeds on 15 of "
        "20 against 17 (rosettes 5/7 against 7/7) at 67 s a recording against 39 (see "
        "docs/method.md)",
    )
    seed: int = 0


@dataclass(frozen=True)
class Segmentation:
    """One cloud split into floor and objects, (N, 3) in the LiDAR frame (objects voxelised).

    `object_normals` (N, 3): the unit normal of each object point's local surface.

    `floor` is None when no plane with `min_floor_points` inliers was found. `floor_rms_m` is the
    RMS distance of the floor inliers to the refined plane (NaN without floor).
    """

    floor: Plane | None
    floor_inliers: int
    object_points: Points
    object_normals: Points
    cluster_count: int
    input_points: int
    floor_rms_m: float
    seconds: float
    quadric_object_points: Points | None = None
    """The object points as the quadric surface model places them (N, 3, same normals), where
    the beam quadric's fit made them on the way (`LocalSurfaces.along_normals`): the surface
    sensitivity's alternative without fitting again. None for other models and settings."""


def fit_plane(points: Points) -> tuple[NDArray[np.float64], float, float]:
    """Least-squares plane through (N >= 3, 3) points: unit normal (sign arbitrary), offset, RMS."""
    centroid = points.mean(axis=0)
    centred = points - centroid
    _, singular, vt = np.linalg.svd(centred.T @ centred)
    normal = vt[2]
    rms = float(np.sqrt(max(singular[2], 0.0) / len(points)))
    return normal, float(-normal @ centroid), rms


def fit_plane_along_beams(
    points: Points,
    normal: NDArray[np.float64],
    offset: float,
    *,
    iterations: int = 1,
) -> tuple[NDArray[np.float64], float, float]:
    """The plane `normal . x + offset = 0` refitted to (N >= 3, 3) points of one LiDAR in its own
    frame (seen from the origin), starting from that plane: unit normal (oriented as `normal`),
    offset and the RMS distance.

    A LiDAR's noise lies along its beams. Least squares on the points themselves (`fit_plane`)
    then tilts the plane wherever the beams meet it obliquely and from one side, as a LiDAR
    pitched down at the floor meets it: a point's tangential coordinate and its distance to the
    plane carry the same range error, so their product does not average out (on a 32-beam LiDAR
    0.32 m above the floor with 3 cm of range noise, the floor came out 0.08 deg tilted at every
    stop). Here the tangential coordinates are taken where each beam meets the current plane,
    which the range noise does not move, so the distances' errors average out at the true plane
    (an instrumental-variable fit); each of the `iterations` steps is linear, and a few from a
    plane within the RANSAC band settle it.
    """
    directions = points / np.linalg.norm(points, axis=1, keepdims=True)
    normal = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
    for _ in range(iterations):
        # Coordinates along two tangents and the normal: of the points, and of their beams.
        axes = np.column_stack([tangent_basis(normal), normal])
        local = points @ axes
        beams = directions @ axes
        distances = local[:, 2] + offset
        # A beam (nearly) parallel to the plane meets it nowhere near its point: keep the point.
        along = distances / np.where(np.abs(beams[:, 2]) > 1e-3, beams[:, 2], np.inf)
        instruments = np.ones((len(points), 3))
        instruments[:, :2] = local[:, :2] - along[:, None] * beams[:, :2]
        # lstsq: a floor seen along one line leaves a tilt undetermined; it then stays put.
        step = np.linalg.lstsq(
            instruments.T @ instruments, -(instruments.T @ distances), rcond=1e-12
        )[0]
        updated = normal + axes[:, :2] @ step[:2]
        length = float(np.linalg.norm(updated))
        normal = updated / length
        offset = (offset + float(step[2])) / length
    distances = points @ normal + offset
    rms = float(np.sqrt(np.mean(distances**2)))
    return normal, float(offset), rms


def lower_envelope(points: Points, up: NDArray[np.float64], cell_m: float) -> NDArray[np.int64]:
    """Indices of the lowest of the (N, 3) `points` along `up` (3,, unit) in each square cell of
    edge `cell_m` across it: where walls and shelves fill the view the floor is a small part of
    a cloud, but the bottom of every column the LiDAR sees is the floor or stands on it."""
    across = points @ tangent_basis(up)
    keys = voxel_keys(np.column_stack([across, np.zeros(len(points))]), cell_m, "floor_cell_m")
    order = np.lexsort((points @ up, keys))
    first = np.ones(len(order), dtype=bool)
    first[1:] = keys[order[1:]] != keys[order[:-1]]
    lowest: NDArray[np.int64] = order[first]
    return lowest


def _floor_score(
    points: Points, normals: NDArray[np.float64], offsets: NDArray[np.float64], distance_m: float
) -> NDArray[np.int64]:
    """(P,) each plane's points of (N, 3) `points` within `distance_m`, less those beyond it below
    the plane: a LiDAR cannot see below the floor, so every point there tells against a plane
    (a shelf top, or a plane through the walls, has the floor under it)."""
    distances = points @ normals.T
    distances += offsets
    # count_nonzero: a boolean sum along an axis casts every element first (a third slower).
    score: NDArray[np.int64] = np.count_nonzero(
        np.abs(distances) < distance_m, axis=0
    ) - np.count_nonzero(distances <= -distance_m, axis=0)
    return score


def _floor_hypotheses(
    candidates: Points,
    scored: Points,
    up: NDArray[np.float64],
    *,
    distance_m: float,
    iterations: int,
    max_tilt_deg: float,
    rng: np.random.Generator,
    keep: int,
) -> list[tuple[NDArray[np.float64], float]]:
    """The `keep` best of `iterations` planes through three random `candidates` (M, 3) tilted at
    most `max_tilt_deg` from `up`, by `_floor_score` on `scored` (S, 3); best first."""
    samples = candidates[rng.integers(0, len(candidates), size=(iterations, 3))]
    normals = np.cross(samples[:, 1] - samples[:, 0], samples[:, 2] - samples[:, 0])
    lengths = np.linalg.norm(normals, axis=1)
    valid = lengths > 1e-12
    normals = normals[valid] / lengths[valid, None]
    normals *= np.sign(normals @ up)[:, None]
    tilted = normals @ up >= np.cos(np.radians(max_tilt_deg))
    normals = normals[tilted]
    offsets = -np.einsum("ij,ij->i", normals, samples[valid][tilted, 0])
    best = np.argsort(-_floor_score(scored, normals, offsets, distance_m), kind="stable")[:keep]
    return [(normals[i], float(offsets[i])) for i in best]


def _refit(
    points: Points,
    plane: tuple[NDArray[np.float64], float],
    up: NDArray[np.float64],
    *,
    distance_m: float,
    min_points: int,
    fit_points: int | None,
    max_refits: int,
    rng: np.random.Generator,
) -> tuple[NDArray[np.float64], float, float] | None:
    """`plane` refitted by least squares to its inliers among (N, 3) `points` (on at most
    `fit_points` random ones), again and again until it moves by less than 1 % of the band (at
    most `max_refits` times): normal (along `up`), offset and the inliers' RMS distance; None
    when fewer than `min_points` inliers are left."""
    normal, offset = plane
    rms = float("nan")
    for _ in range(max_refits):
        index = np.flatnonzero(np.abs(points @ normal + offset) < distance_m)
        if len(index) < max(3, min_points):
            return None
        if fit_points is not None and len(index) > fit_points:
            # The noise averages out long before the last of ~100k inliers.
            index = index[rng.integers(0, len(index), size=fit_points)]
        previous = offset
        normal, offset, rms = fit_plane(points[index])
        if normal @ up < 0:
            normal, offset = -normal, -offset
        if abs(offset - previous) < 0.01 * distance_m:
            break
    return normal, offset, rms


def _best_contender(
    sample: Points,
    hypotheses: list[tuple[NDArray[np.float64], float]],
    up: NDArray[np.float64],
    *,
    distance_m: float,
    max_refits: int,
    rng: np.random.Generator,
) -> tuple[NDArray[np.float64], float] | None:
    """The best of the `hypotheses` once each is settled on `sample` (`_refit`) and scored there
    again (`_floor_score`): normal and offset; None when none keeps three inliers.

    A floor seen as a narrow strip at the walls' feet is a few % of the cloud: a few dozen of
    the scored points, too few to tell it from a plane tilted through it and the feet. The
    contenders, each settled on the sample, are told apart on ten times as many."""
    settled = [
        _refit(
            sample,
            plane,
            up,
            distance_m=distance_m,
            min_points=3,
            fit_points=None,
            max_refits=max_refits,
            rng=rng,
        )
        for plane in hypotheses
    ]
    contending = [plane for plane in settled if plane is not None]
    if not contending:
        return None
    scores = _floor_score(
        sample,
        np.array([normal for normal, _, _ in contending]),
        np.array([offset for _, offset, _ in contending]),
        distance_m,
    )
    normal, offset, _ = contending[int(np.argmax(scores))]
    return normal, offset


ALONG_BEAMS_REFITS = 4
"""How often `find_floor(along_beams=True)` takes the inliers about its last plane and fits the
plane along their beams again."""


def _refit_along_beams(
    points: Points,
    plane: tuple[NDArray[np.float64], float, float],
    *,
    distance_m: float,
    fit_points: int | None,
    rng: np.random.Generator,
) -> tuple[NDArray[np.float64], float, float]:
    """`plane` (normal, offset, RMS) fitted `ALONG_BEAMS_REFITS` times along the beams
    (`fit_plane_along_beams`) to its inliers among (N, 3) `points`, each time those within
    `distance_m` of the last plane. They are drawn from the points within twice the band of the
    first plane, once (at most `fit_points` of them): the refits move the plane by far less than
    the band, and a pass over a whole cloud per refit costs more than the fit."""
    normal, offset, rms = plane
    index = np.flatnonzero(np.abs(points @ normal + offset) < 2.0 * distance_m)
    if fit_points is not None and len(index) > fit_points:
        index = index[rng.integers(0, len(index), size=fit_points)]
    near = points[index]
    for _ in range(ALONG_BEAMS_REFITS):
        inliers = near[np.abs(near @ normal + offset) < distance_m]
        if len(inliers) < 3:
            break
        normal, offset, rms = fit_plane_along_beams(inliers, normal, offset)
    return normal, offset, rms


def find_floor(
    points: Points,
    up: NDArray[np.float64],
    *,
    distance_m: float,
    iterations: int,
    scored_points: int,
    max_tilt_deg: float,
    min_points: int,
    rng: np.random.Generator,
    fit_points: int | None = None,
    cell_m: float = 0.25,
    envelope_points: int = 20_000,
    max_refits: int = 10,
    contenders: int = 5,
    along_beams: bool = False,
) -> tuple[Plane, NDArray[np.bool_], float] | None:
    """RANSAC for the floor: the plane whose normal is within `max_tilt_deg` of `up` (3,) with
    most inliers and fewest points below it (`_floor_score`), drawn from the lower envelope
    (`lower_envelope` of `envelope_points` random points, columns of `cell_m`).

    The `contenders` best hypotheses (scored on `scored_points` random points) are refitted on
    the envelope's random points and scored there again; the best is refitted on all `points`
    (see `_refit`; `along_beams`: the points are a LiDAR's in its own frame, and the plane is
    fitted again on its inliers with their noise along the beams, `fit_plane_along_beams`,
    `ALONG_BEAMS_REFITS` times). Returns that plane (normal oriented along `up`), the inlier
    mask over `points` and the inliers' RMS distance; None when no such plane has `min_points`
    inliers.
    """
    n = len(points)
    if n < max(3, min_points):
        return None
    sample = points[rng.integers(0, n, size=min(n, envelope_points))]
    hypotheses = _floor_hypotheses(
        sample[lower_envelope(sample, up, cell_m)],
        points[rng.integers(0, n, size=min(n, scored_points))],
        up,
        distance_m=distance_m,
        iterations=iterations,
        max_tilt_deg=max_tilt_deg,
        rng=rng,
        keep=contenders,
    )
    best = _best_contender(
        sample, hypotheses, up, distance_m=distance_m, max_refits=max_refits, rng=rng
    )
    if best is None:
        return None
    refitted = _refit(
        points,
        best,
        up,
        distance_m=distance_m,
        min_points=min_points,
        fit_points=fit_points,
        max_refits=max_refits,
        rng=rng,
    )
    if refitted is None:
        return None
    normal, offset, rms = refitted
    if along_beams:
        normal, offset, rms = _refit_along_beams(
            points, (normal, offset, rms), distance_m=distance_m, fit_points=fit_points, rng=rng
        )
    inliers = np.abs(points @ normal + offset) < distance_m
    if inliers.sum() < max(3, min_points) or normal @ up < np.cos(np.radians(max_tilt_deg)):
        return None
    return Plane(normal=normal, offset=offset), inliers, rms


# The 13 neighbour offsets of a cell in one half of its 26-neighbourhood (the other half are the
# same edges seen from the other end).
_HALF_NEIGHBOURHOOD = np.array(
    [
        (dx, dy, dz)
        for dx in (-1, 0, 1)
        for dy in (-1, 0, 1)
        for dz in (-1, 0, 1)
        if (dx, dy, dz) > (0, 0, 0)
    ],
    dtype=np.int64,
)
_NEIGHBOUR_KEY_OFFSETS = pack_cells(_HALF_NEIGHBOURHOOD)


def euclidean_clusters(points: Points, radius: float) -> NDArray[np.int64]:
    """Label (N,) of each point's cluster, on a grid of cubic cells of edge `radius`: points in
    touching cells (26-neighbourhood) share a cluster. So two points closer than `radius` always
    share one, and points up to 2 * sqrt(3) * radius apart may; a grid is ten times faster than
    the radius graph of the points themselves. Points beyond the grid raise `BadInputError`."""
    if len(points) == 0:
        return np.zeros(0, dtype=np.int64)
    occupied, cell_of = np.unique(
        voxel_keys(points, radius, "cluster_radius_m"), return_inverse=True
    )
    # A neighbour cell's key is the cell's key plus the packed offset (the grid keeps a margin).
    neighbours = occupied[:, None] + _NEIGHBOUR_KEY_OFFSETS[None, :]
    position = np.searchsorted(occupied, neighbours)
    found = position < len(occupied)
    found[found] = occupied[position[found]] == neighbours[found]
    rows = np.broadcast_to(np.arange(len(occupied))[:, None], found.shape)[found]
    graph = coo_matrix(
        (np.ones(len(rows), dtype=np.int8), (rows, position[found])),
        shape=(len(occupied), len(occupied)),
    )
    _, labels = connected_components(graph, directed=False)
    result: NDArray[np.int64] = labels[cell_of.reshape(-1)].astype(np.int64)
    return result


FloorFit = tuple[Plane, NDArray[np.bool_], float]
"""A cloud's floor: the plane, the inlier mask over the cloud and the inliers' RMS distance (m)."""


def fit_floor(
    points: Points, up: NDArray[np.float64], config: SegmentationConfig
) -> FloorFit | None:
    """The floor of (N, 3) points of one LiDAR at one stop (see `find_floor`), None if none.

    `up` (3,) is the expected floor normal in the LiDAR frame (base z through the initial
    extrinsics); it picks the floor among planes and orients its normal. The floor is found among
    the raw points (a sample scores the hypotheses, a sample refits the plane).
    """
    return find_floor(
        np.asarray(points, dtype=np.float64),
        np.asarray(up, dtype=np.float64) / np.linalg.norm(up),
        distance_m=config.floor_distance_m,
        iterations=config.ransac_iterations,
        scored_points=config.ransac_scored_points,
        max_tilt_deg=config.max_floor_tilt_deg,
        min_points=config.min_floor_points,
        rng=np.random.default_rng(config.seed),
        fit_points=config.floor_fit_points,
        cell_m=config.floor_cell_m,
        envelope_points=config.floor_envelope_points,
        along_beams=config.floor_fit == "along_beams",
    )


def above_floor(points: Points, floor: Plane, config: SegmentationConfig) -> NDArray[np.bool_]:
    """(N,) the points high enough above `floor` to be object candidates."""
    mask: NDArray[np.bool_] = points @ floor.normal + floor.offset > config.object_min_height_m
    return mask


def segment(points: Points, up: NDArray[np.float64], config: SegmentationConfig) -> Segmentation:
    """Split (N, 3) points of one LiDAR at one stop into floor and objects, in the LiDAR frame.

    `up` (3,) is the expected floor normal in the LiDAR frame (see `fit_floor`). The floor is
    fitted here; `segment_on_floor` takes one fitted already.
    """
    started = time.perf_counter()
    cloud = np.asarray(points, dtype=np.float64)
    result = segment_on_floor(cloud, config, fit_floor(cloud, up, config))
    return dataclasses.replace(result, seconds=time.perf_counter() - started)


def _smoothed(objects: Points, config: SegmentationConfig) -> LocalSurfaces:
    """Object points (N, 3, the sensor at the origin) on their local surfaces, and its normals;
    with `surface_debias` the fit's own offset from the surface taken back along the normals
    (and then no quadric projection kept beside them)."""

    def fit(points: Points) -> LocalSurfaces:
        return local_surfaces(
            points,
            config.surface_neighbours,
            config.surface_centre_neighbours,
            quadric=config.surface_model != "plane",
            along_beams=config.surface_model in ("beam_quadric", "beam_fit"),
            normals_along_beams=config.surface_model == "beam_fit",
            passes=config.surface_passes,
        )

    surfaces = fit(objects)
    if config.surface_patch == "noise":
        patch = patch_neighbours(objects, surfaces, config)
        if patch != config.surface_neighbours:
            config = config.model_copy(update={"surface_neighbours": patch})
            surfaces = fit(objects)
    if config.surface_debias == "bootstrap":
        offsets = smoothing_offsets(
            objects,
            surfaces.projected,
            surfaces.normals,
            lambda points: fit(points).projected,
            config.surface_neighbours,
            np.random.default_rng(config.seed),
        )
        projected = surfaces.projected - offsets[:, None] * surfaces.normals
        return LocalSurfaces(projected, surfaces.normals)
    return surfaces


REFERENCE_RANGE_NOISE_M = 0.02
"""The range noise (one sigma) at which `surface_neighbours` is the patch (`surface_patch:
noise`): the Mid-70's, on which the fixed patch was chosen."""

PATCH_LIMITS = (10, 400)
"""The fewest and most neighbours a `surface_patch: noise` patch may have (a quadric needs 10)."""


def patch_neighbours(objects: Points, surfaces: LocalSurfaces, config: SegmentationConfig) -> int:
    """The patch for `surface_patch: noise`: `surface_neighbours` scaled by the cloud's range
    noise over `REFERENCE_RANGE_NOISE_M` and by the voxel size over its point spacing.

    A plane fitted to k points of spacing s under noise sigma tilts by about sigma / (R sqrt(k))
    over a patch of radius R = s sqrt(k / pi), i.e. as sigma / (s k): holding the tilt, k grows
    as sigma / s. The noise is what the first fit (`surfaces`, with `surface_neighbours`) took
    away along the beams (`range_noise_from_smoothing`); the spacing comes from the radius that
    holds a patch, s = r_k sqrt(pi / k) (median over the points). A cloud too small or too
    oblique to measure its noise keeps `surface_neighbours`."""
    k = config.surface_neighbours
    if len(objects) <= k:
        return k
    sigma = range_noise_from_smoothing(objects, surfaces.projected, surfaces.normals)
    if sigma is None or sigma <= 0.0:
        return k
    distances, _ = KDTree(objects).query(objects, k=k)
    spacing = float(np.median(distances[:, -1])) * np.sqrt(np.pi / k)
    if spacing <= 0.0:
        return k
    scaled = k * (sigma / REFERENCE_RANGE_NOISE_M) * (config.voxel_size_m / spacing)
    return int(np.clip(round(scaled), *PATCH_LIMITS))


def segment_on_floor(
    points: Points, config: SegmentationConfig, found: FloorFit | None
) -> Segmentation:
    """`segment` with the cloud's floor fitted beforehand (`fit_floor` on these points; None:
    it found none, and then nothing can be told apart from the floor: no objects)."""
    started = time.perf_counter()
    cloud = np.asarray(points, dtype=np.float64)
    # Only the points above the floor are voxelised: the floor is ~90 % of a full-rate cloud and
    # voxelising it would cost more than everything else in this stage.
    if found is None:
        floor, floor_inliers, rms = None, 0, float("nan")
        candidates = cloud[:0]
    else:
        floor, floor_mask, rms = found
        floor_inliers = int(np.count_nonzero(floor_mask))
        candidates = voxel_downsample(cloud[above_floor(cloud, floor, config)], config.voxel_size_m)
    labels = euclidean_clusters(candidates, config.cluster_radius_m)
    sizes = np.bincount(labels) if len(labels) else np.zeros(0, dtype=np.int64)
    kept = sizes >= config.min_cluster_points
    objects = candidates[kept[labels]] if len(labels) else candidates
    normals = np.zeros((0, 3))
    quadric_objects = None
    if len(objects) >= 3:
        surfaces = _smoothed(objects, config)
        normals = surfaces.normals
        # The sensor sits at the origin: the beam to p is p / |p|.
        cos = np.abs(np.einsum("ni,ni->n", normals, objects)) / np.linalg.norm(objects, axis=1)
        seen = cos >= config.min_incidence_cos
        if config.smooth_objects and surfaces.along_normals is not None:
            quadric_objects = surfaces.along_normals[seen]
        objects = (surfaces.projected if config.smooth_objects else objects)[seen]
        normals = normals[seen]
    else:
        objects = objects[:0]
    return Segmentation(
        floor=floor,
        floor_inliers=floor_inliers,
        object_points=objects,
        object_normals=normals,
        cluster_count=int(kept.sum()),
        input_points=len(points),
        floor_rms_m=rms,
        seconds=time.perf_counter() - started,
        quadric_object_points=quadric_objects,
    )
