"""Where segmentation's object points lie against the true surfaces (issue 13): the signed offset
of each point behind the object surface it belongs to, raw and smoothed.

    .venv/bin/python -m tests.bench.bench_surface_bias [--seeds 1000,1013]
        [--recordings /tmp/honest/cache/recordings/rate-0.3] [--synthetic-only]
        [--surface-model MODEL] [--cases spinning set1-box]

For each seed, the recording `RECORDINGS/seed-N/recording` is read and taken through the
pipeline's stages up to segmentation (moving points, stage 1) with the default config; each
LiDAR's cloud of each stop is then segmented twice, with and without `smooth_objects` (the same
points, the same kept ones: smoothing only moves them). The object points go to the world with
the TRUE extrinsics and base poses (`truth.json`) and are measured against the true objects:
`ray` is a point's range less the range at which its beam (from the true sensor position
through the point) first meets a true object surface: positive behind the surface, what a range
bias would do. `behind` is the same along the true normal (`ray * |cos|`). Points whose beam
meets no object within 0.15 m of them (beyond a silhouette, the floor's edge) are left out and
counted as missed.

`--cases` measures bench_calibration's fixed scenarios the same way (synthesised in memory,
seeds 0 to `--case-seeds` - 1). A synthetic case (one cylinder, one box face, seen by one
sensor over repeated scans with given range noise, segmented by the same `segment_on_floor`)
is measured the same way.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import get_args  # noqa: E402

import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from pipeline.config import PipelineConfig  # noqa: E402
from pipeline.geometry import Plane  # noqa: E402
from pipeline.problem import CalibrationProblem  # noqa: E402
from pipeline.segmentation import FloorFit, SegmentationConfig, segment_on_floor  # noqa: E402
from pipeline.synth.objects import ObjectKind, SceneObject  # noqa: E402
from pipeline.synth.truth import Truth  # noqa: E402
from pipeline.transforms import Matrix4, make_transform  # noqa: E402

MIN_COS = 0.12
"""Beams more edge-on than this to the true surface are left out of the along-beam offset."""


@dataclass(frozen=True)
class Offsets:
    """Per point (N,): `ray` (m, its range less the range at which its beam first meets a true
    surface) and `behind` (m, the same times |cos| of beam and true normal there: the offset
    along the normal); `missed`: points whose beam meets no object within the limit."""

    ray: NDArray[np.float64]
    behind: NDArray[np.float64]
    missed: int


def nearest_signed_distance(
    points: NDArray[np.float64], objects: Sequence[SceneObject]
) -> NDArray[np.float64]:
    """Signed distance (N,) of world `points` (N, 3) to the union of `objects`."""
    result: NDArray[np.float64] = np.min(
        np.stack([obj.signed_distance(points) for obj in objects], axis=1), axis=1
    )
    return result


def first_hits(
    origin: NDArray[np.float64],
    directions: NDArray[np.float64],
    objects: Sequence[SceneObject],
    max_range_m: float,
) -> NDArray[np.float64]:
    """Range (N,) at which unit rays `directions` (N, 3) from `origin` (3,) first meet one of
    `objects` (sphere tracing on their signed distance); NaN where they do not within
    `max_range_m`. `origin` must lie outside every object."""
    t = np.zeros(len(directions))
    active = np.ones(len(directions), dtype=bool)
    for _ in range(400):
        rows = np.flatnonzero(active)
        if len(rows) == 0:
            break
        step = nearest_signed_distance(origin + directions[rows] * t[rows, None], objects)
        t[rows] += step
        active[rows] = (np.abs(step) > 1e-9) & (t[rows] < max_range_m)
    at = origin + directions * t[:, None]
    hit = (t < max_range_m) & (np.abs(nearest_signed_distance(at, objects)) < 1e-6)
    return np.where(hit, t, np.nan)


def surface_offsets(
    points_in_lidar: NDArray[np.float64],
    T_world_lidar: Matrix4,
    objects: Sequence[SceneObject],
    max_offset_m: float = 0.15,
) -> Offsets:
    """How far behind the true surfaces of `objects` the (N, 3) points in the LiDAR frame lie
    along their beams, the LiDAR placed by `T_world_lidar` (4, 4); see `Offsets`. A point whose
    beam meets the objects further than `max_offset_m` from it (or not at all: beyond their
    silhouette) counts as missed."""
    if len(points_in_lidar) == 0 or not objects:
        return Offsets(np.zeros(0), np.zeros(0), len(points_in_lidar))
    origin = T_world_lidar[:3, 3]
    beam = points_in_lidar @ T_world_lidar[:3, :3].T
    ranges = np.linalg.norm(beam, axis=1)
    beam /= ranges[:, None]
    hit = first_hits(origin, beam, objects, float(ranges.max()) + 1.0)
    ray = ranges - hit
    kept = np.isfinite(ray) & (np.abs(ray) <= max_offset_m)
    beam, ray, hit = beam[kept], ray[kept], hit[kept]
    # The true normal at the hit: the signed distance's gradient (central differences).
    at = origin + beam * hit[:, None]
    step = 1e-5
    normal = np.column_stack(
        [
            nearest_signed_distance(at + step * e, objects)
            - nearest_signed_distance(at - step * e, objects)
            for e in np.eye(3)
        ]
    )
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    cos = np.abs(np.einsum("ni,ni->n", normal, beam))
    return Offsets(ray, ray * cos, int(np.count_nonzero(~kept)))


@dataclass
class Tally:
    """Offsets gathered over clouds, raw and smoothed."""

    raw: list[Offsets]
    smoothed: list[Offsets]

    def row(self, label: str) -> str:
        cells = [label]
        for offsets in (self.raw, self.smoothed):
            behind = np.concatenate([o.behind for o in offsets]) if offsets else np.zeros(0)
            ray = np.concatenate([o.ray for o in offsets]) if offsets else np.zeros(0)
            if len(behind) == 0:
                cells += ["-"] * 5
                continue
            cells += [
                f"{len(behind)}",
                f"{1e3 * behind.mean():+.2f}",
                f"{1e3 * np.median(behind):+.2f}",
                f"{1e3 * ray.mean():+.2f}",
                f"{1e3 * np.median(ray):+.2f}",
            ]
        cells.append(f"{sum(o.missed for o in self.raw)} / {sum(o.missed for o in self.smoothed)}")
        return "| " + " | ".join(cells) + " |"


HEADER = (
    "| {label} | raw points | raw behind mean mm | raw behind median mm | raw ray mean mm "
    "| raw ray median mm | smoothed points | smoothed behind mean mm | smoothed behind median mm "
    "| smoothed ray mean mm | smoothed ray median mm | missed raw / smoothed |\n"
    + "|---" * 12
    + "|"
)


def segmented_pair(
    cloud: NDArray[np.float64], floor: FloorFit | None, config: SegmentationConfig
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The object points of one cloud as segmentation gives them, raw and smoothed (N, 3)."""
    raw = segment_on_floor(cloud, config.model_copy(update={"smooth_objects": False}), floor)
    smoothed = segment_on_floor(cloud, config.model_copy(update={"smooth_objects": True}), floor)
    return raw.object_points, smoothed.object_points


def seed_tallies(
    directory: Path, config: PipelineConfig
) -> tuple[dict[str, tuple[str, float]], dict[str, Tally]]:
    """`stop_tallies` of the recording in `directory` (and its `truth.json`)."""
    from pipeline.io import read_recording
    from pipeline.synth.truth import load_truth

    return stop_tallies(
        read_recording(directory / "recording", config.reader), load_truth(directory), config
    )


def stop_tallies(
    problem: CalibrationProblem, truth: Truth, config: PipelineConfig
) -> tuple[dict[str, tuple[str, float]], dict[str, Tally]]:
    """Per LiDAR frame of `problem`: (model, range noise m) and its `Tally` against `truth`."""
    from pipeline.stages.runner import Listeners, run_stages
    from pipeline.stages.sequence import STAGE_SEQUENCE
    from pipeline.stages.setup import initial_state

    upto = [s for s in STAGE_SEQUENCE if s.name in ("moving_points", "denoise")]
    state, _ = run_stages(initial_state(problem, config.frames), config, upto, Listeners())
    models = {
        str(m["frame"]): (str(m["model"]["kind"]), float(m["model"]["range_noise_m"]))
        for m in truth.spec["lidars"]
    }
    objects = [obj for obj in truth.objects]
    tallies: dict[str, Tally] = {}
    for index, lidar in enumerate(state.lidars):
        tally = tallies.setdefault(lidar.frame, Tally([], []))
        T_base_lidar = truth.lidar(lidar.frame).T_base_lidar_true
        for j, stop in enumerate(problem.stops):
            middle = 0.5 * (stop.t_start + stop.t_end)
            matches = [s for s in truth.stops if s.t_start <= middle <= s.t_end]
            if not matches:
                continue
            T_world_lidar = matches[0].T_odom_base_true @ T_base_lidar
            cloud, floor = state.filtered(index, j)
            raw, smoothed = segmented_pair(cloud, floor, config.segmentation)
            tally.raw.append(surface_offsets(raw, T_world_lidar, objects))
            tally.smoothed.append(surface_offsets(smoothed, T_world_lidar, objects))
    return models, tallies


def spinning_rays(
    azimuth_deg: tuple[float, float], azimuth_step_deg: float = 0.2, beams: int = 32
) -> NDArray[np.float64]:
    """Unit beams (N, 3) of a spinning LiDAR with `beams` channels from -25 to 15 deg elevation,
    over the azimuth span `azimuth_deg` every `azimuth_step_deg`."""
    azimuth = np.radians(np.arange(azimuth_deg[0], azimuth_deg[1], azimuth_step_deg))
    elevation = np.radians(np.linspace(-25.0, 15.0, beams))
    a, e = np.meshgrid(azimuth, elevation)
    return np.column_stack(
        [(np.cos(e) * np.cos(a)).ravel(), (np.cos(e) * np.sin(a)).ravel(), np.sin(e).ravel()]
    )


SENSOR_HEIGHT_M = 1.0
"""The synthetic sensor's height above its floor (z = -1 in its frame)."""


def synthetic_object(kind: str, range_m: float) -> SceneObject:
    """A cylinder (radius 0.15 m) or a box (0.4 m cube, one face square to the sensor) standing
    on the floor z = -SENSOR_HEIGHT_M, `range_m` ahead of the sensor along x."""
    if kind == "cylinder":
        dims = {"radius": 0.15, "height": 0.5}
        height = dims["height"]
        T = make_transform(np.eye(3), np.array([range_m + 0.15, 0.0, -SENSOR_HEIGHT_M + 0.25]))
        return SceneObject(ObjectKind.CYLINDER, dims, T, 0.6)
    dims = {"x": 0.4, "y": 0.4, "z": 0.5}
    height = dims["z"]
    T = make_transform(np.eye(3), np.array([range_m + 0.2, 0.0, -SENSOR_HEIGHT_M + 0.5 * height]))
    return SceneObject(ObjectKind.BOX, dims, T, 0.6)


def synthetic_cloud(
    obj: SceneObject,
    range_noise_m: float,
    scans: int,
    rng: np.random.Generator,
    bias_m: float = 0.0,
) -> NDArray[np.float64]:
    """`scans` scans (N, 3) of `obj` by a spinning LiDAR at the origin: the true hits moved
    along their beams by `bias_m` plus Gaussian range noise of `range_noise_m` per return."""
    beams = spinning_rays((-30.0, 30.0))
    ranges = first_hits(np.zeros(3), beams, [obj], 30.0)
    beams, ranges = beams[np.isfinite(ranges)], ranges[np.isfinite(ranges)]
    noisy = ranges[None, :] + bias_m + rng.normal(0.0, range_noise_m, (scans, len(ranges)))
    result: NDArray[np.float64] = (beams[None, :, :] * noisy[:, :, None]).reshape(-1, 3)
    return result


def synthetic_tally(
    kind: str,
    range_noise_m: float,
    config: SegmentationConfig,
    range_m: float = 3.0,
    scans: int = 10,
    repeats: int = 10,
    bias_m: float = 0.0,
) -> Tally:
    """Segmentation's object points of one synthetic object (see `synthetic_object`), measured,
    over `repeats` draws of the noise."""
    obj = synthetic_object(kind, range_m)
    floor: FloorFit = (
        Plane(normal=np.array([0.0, 0.0, 1.0]), offset=SENSOR_HEIGHT_M),
        np.zeros(0, dtype=bool),
        0.0,
    )
    tally = Tally([], [])
    for seed in range(repeats):
        rng = np.random.default_rng(seed)
        cloud = synthetic_cloud(obj, range_noise_m, scans, rng, bias_m)
        raw, smoothed = segmented_pair(cloud, floor, config)
        tally.raw.append(surface_offsets(raw, np.eye(4), [obj]))
        tally.smoothed.append(surface_offsets(smoothed, np.eye(4), [obj]))
    return tally


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--seeds", default="1000", help="e.g. 1000,1013 or 1000-1003")
    parser.add_argument(
        "--recordings", type=Path, default=Path("/tmp/honest/cache/recordings/rate-0.3")
    )
    parser.add_argument("--synthetic-only", action="store_true")
    parser.add_argument(
        "--cases", nargs="*", default=[], help="fixed scenarios too (bench_calibration's cases)"
    )
    parser.add_argument("--case-seeds", type=int, default=2, help="seeds 0.. of each case")
    parser.add_argument("--rate", type=float, default=0.3, help="the cases' rate scale")
    parser.add_argument(
        "--surface-model",
        choices=get_args(SegmentationConfig.model_fields["surface_model"].annotation),
        default=None,
    )
    parser.add_argument(
        "--surface-debias",
        choices=get_args(SegmentationConfig.model_fields["surface_debias"].annotation),
        default=None,
    )
    args = parser.parse_args(argv)
    from tests.bench.bench_random import parse_seeds

    config = PipelineConfig()
    changes = {
        name: value
        for name, value in (
            ("surface_model", args.surface_model),
            ("surface_debias", args.surface_debias),
        )
        if value is not None
    }
    config = config.model_copy(
        update={"segmentation": config.segmentation.model_copy(update=changes)}
    )
    print(
        f"surface model: {config.segmentation.surface_model}, debias "
        f"{config.segmentation.surface_debias}; behind/ray > 0: behind the surface"
    )
    print("\nSynthetic: one object 3 m ahead, spinning LiDAR, 10 scans")
    print(HEADER.format(label="object / range noise"))
    for kind in ("cylinder", "box"):
        for noise in (0.0, 0.005, 0.01, 0.02, 0.03):
            tally = synthetic_tally(kind, noise, config.segmentation)
            print(tally.row(f"{kind} {1e3 * noise:.0f} mm"))
    if args.synthetic_only:
        return
    from pipeline.synth import simulate_problem

    for case in args.cases:
        for case_seed in range(args.case_seeds):
            problem, truth = simulate_problem(case, case_seed, args.rate)
            models, found = stop_tallies(problem, truth, config)
            print(f"\nCase {case} seed {case_seed} (rate {args.rate:g})")
            print(HEADER.format(label="LiDAR (model, range noise)"))
            for frame, tally in found.items():
                model, noise = models[frame]
                print(tally.row(f"{frame} ({model}, {1e3 * noise:.0f} mm)"))
    for seed in parse_seeds(args.seeds):
        models, found = seed_tallies(args.recordings / f"seed-{seed}", config)
        print(f"\nSeed {seed}")
        print(HEADER.format(label="LiDAR (model, range noise)"))
        for frame, tally in found.items():
            model, noise = models[frame]
            print(tally.row(f"{frame} ({model}, {1e3 * noise:.0f} mm)"))


if __name__ == "__main__":
    main()
