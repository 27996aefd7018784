"""Stage 1 on the synthesiser's labelled clouds: how well each filter removes bleeding points.

    .venv/bin/python -m tests.bench.bench_denoise [--scenes set1-box,set1-cylinder,set1-capsule]
        [--seeds 10,11] [--stop-step 2] [--repeats 5]
    .venv/bin/python -m tests.bench.bench_denoise --bleeding-draws 24 [--draw-stops 0,8]
        [--first-draw 0]

`--bleeding-draws N`: instead, the randomised bleeding models of `pipeline.synth.bleeding`
(draws F..F+N-1 with F = `--first-draw`, default 0: beam, scan pattern, scene; e.g. draws 0-19 to
judge changes by and 20-39 held out), every LiDAR at the stops `--draw-stops`, each filter
judging every point: precision / recall / F per draw (pooled over its clouds), their mean and
minimum, and CPU seconds per 100k points. `range_gap` runs twice: estimating the range noise and
scan pattern from each cloud, and given the LiDAR model's. A last column is no filter
(`LABEL_RULE`): it removes the points whose measured position lies farther than three range-noise
sigmas from every true surface, the label's rule on the noisy point: how far range noise alone
blurs the labels.

Clouds are the stop clouds `simulate_problem` gives the pipeline (every LiDAR, every
`--stop-step`-th stop, full point rate). Positive = a removed point that is truly bleeding;
precision, recall and F-score are pooled over a scene's clouds. Every method runs with the
paper's parameters (`k = 20`, `C_s = 0.01`, `C_r = 3.0`); `pattern` adds its own defaults. The
seeds differ from those `pattern`'s defaults were chosen on (0, 1). Prints markdown tables: scores
per scene, the clean points removed near the observation centre (the paper's blind disc), and
seconds per 100k points (wall and CPU; single-threaded, then on every core in a child process:
pykdtree's kNN query is OpenMP-parallel; the load average is printed with it). The rows
"pattern, above the floor" and "pipeline" run the filter as `pipeline.calibrate` does: only the
points standing above the cloud's floor are judged; the pipeline's own default has a stricter
density ratio (see `PipelineConfig.denoise`).
"""

from __future__ import annotations

import os

# Single-threaded numbers, as a worker process runs (DESIGN.md pins BLAS threads there too);
# these must be set before numpy is imported.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402
from collections.abc import Callable  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from functools import partial  # noqa: E402

import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from pipeline.config import PipelineConfig  # noqa: E402
from pipeline.denoise import (  # noqa: E402
    DenoiseConfig,
    DenoiseMethod,
    DenoiseResult,
    denoise,
    knn_mean_distances,
    observation_centre,
)
from pipeline.segmentation import fit_floor  # noqa: E402
from pipeline.stages.denoise_stage import denoise_above_floor  # noqa: E402
from pipeline.synth.bleeding import draw_bleeding_case  # noqa: E402
from tests.pipeline.denoise.clouds import (  # noqa: E402
    BeamCloud,
    LabelledCloud,
    bleeding_stop_clouds,
    synth_stop_clouds,
)

DEFAULT_SCENES = ("set1-box", "set1-cylinder", "set1-capsule")
CENTRE_DISC_M = 0.2


@dataclass
class Tally:
    """Pooled counts of one method on one scene."""

    true_pos: int = 0
    false_pos: int = 0
    false_neg: int = 0
    clean_near_centre: int = 0
    clean_near_centre_removed: int = 0

    def add(self, keep: NDArray[np.bool_], cloud: LabelledCloud, near: NDArray[np.bool_]) -> None:
        removed, bleeding = ~keep, cloud.is_bleeding
        self.true_pos += int(np.count_nonzero(removed & bleeding))
        self.false_pos += int(np.count_nonzero(removed & ~bleeding))
        self.false_neg += int(np.count_nonzero(keep & bleeding))
        self.clean_near_centre += int(np.count_nonzero(near & ~bleeding))
        self.clean_near_centre_removed += int(np.count_nonzero(near & ~bleeding & removed))

    def scores(self) -> tuple[float, float, float]:
        precision = self.true_pos / max(self.true_pos + self.false_pos, 1)
        recall = self.true_pos / max(self.true_pos + self.false_neg, 1)
        f_score = 2 * self.true_pos / max(2 * self.true_pos + self.false_pos + self.false_neg, 1)
        return precision, recall, f_score


ABOVE_FLOOR = "pattern, above the floor"
"""The default filter judging only the points above the cloud's floor, as the pipeline runs it
(the rest are kept, so bleeding points near the floor count as missed)."""
PIPELINE = f"pipeline (above the floor, density ratio {PipelineConfig().denoise.density_ratio})"
"""Stage 1 exactly as `pipeline.calibrate` runs it by default."""


def filters(cloud: LabelledCloud) -> dict[str, Callable[[], DenoiseResult]]:
    """Every method on `cloud` with the paper's parameters, and the pipeline's way of running
    the default."""
    actions: dict[str, Callable[[], DenoiseResult]] = {
        method.value: partial(
            denoise, cloud.points, DenoiseConfig(method=method), cloud.optical_axis
        )
        for method in DenoiseMethod
    }
    pipeline = PipelineConfig()
    floor = fit_floor(cloud.points, cloud.up, pipeline.segmentation)
    if floor is not None:
        above = pipeline.model_copy(update={"denoise": DenoiseConfig()})
        actions[ABOVE_FLOOR] = partial(denoise_above_floor, cloud.points, floor[0], above)
        actions[PIPELINE] = partial(denoise_above_floor, cloud.points, floor[0], pipeline)
    return actions


def score_scene(scene: str, seeds: list[int], stop_step: int) -> tuple[dict[str, Tally], int, int]:
    tallies: dict[str, Tally] = defaultdict(Tally)
    points = bleeding = 0
    for cloud in synth_stop_clouds(scene, seeds, stop_step):
        points += len(cloud.points)
        bleeding += int(cloud.is_bleeding.sum())
        centre = observation_centre(cloud.points, cloud.optical_axis)
        near = np.linalg.norm(cloud.points - centre, axis=1) < CENTRE_DISC_M
        for label, action in filters(cloud).items():
            tallies[label].add(action().keep, cloud, near)
    return tallies, points, bleeding


def time_per_100k(cloud: LabelledCloud, repeats: int) -> list[tuple[str, float, float]]:
    """(label, wall s, CPU s) per 100k points of the cloud: medians over `repeats` runs."""
    scale = 100_000 / len(cloud.points)
    cases: list[tuple[str, Callable[[], object]]] = [
        ("kNN only (k = 20)", partial(knn_mean_distances, cloud.points, 20)),
        *filters(cloud).items(),
    ]
    rows = []
    for label, action in cases:
        walls, cpus = [], []
        for _ in range(repeats):
            wall, cpu = time.perf_counter(), time.process_time()
            action()
            walls.append(time.perf_counter() - wall)
            cpus.append(time.process_time() - cpu)
        rows.append((label, float(np.median(walls)) * scale, float(np.median(cpus)) * scale))
    return rows


def timing_table(scenes: list[str], seeds: list[int], repeats: int) -> str:
    cloud = next(synth_stop_clouds(scenes[0], seeds[:1]))
    rows = time_per_100k(cloud, repeats)
    threads = os.environ.get("OMP_NUM_THREADS", "all")
    lines = [
        f"## Seconds per 100k points ({len(cloud.points)}-point cloud, median of {repeats}; "
        f"OMP_NUM_THREADS={threads}; load average {os.getloadavg()[0]:.1f} on "
        f"{os.cpu_count()} cores)\n",
        "| method | wall s | CPU s |",
        "|---|---:|---:|",
    ]
    lines += [f"| {label} | {wall:.3f} | {cpu:.3f} |" for label, wall, cpu in rows]
    return "\n".join(lines)


def draw_filters(beam: BeamCloud) -> dict[str, Callable[[], DenoiseResult]]:
    """The filters the bleeding-model table compares, each judging every point of the cloud."""
    cloud = beam.cloud
    paper = {m: DenoiseConfig(method=m) for m in (DenoiseMethod.SOR, DenoiseMethod.DSOR)}
    actions: dict[str, Callable[[], DenoiseResult]] = {
        "range_gap (estimated)": partial(
            denoise, cloud.points, DenoiseConfig(method=DenoiseMethod.RANGE_GAP)
        ),
        "range_gap (LiDAR model)": partial(
            denoise,
            cloud.points,
            DenoiseConfig(method=DenoiseMethod.RANGE_GAP),
            range_noise_m=beam.range_noise_m,
            scan_pattern=beam.scan_pattern,
        ),
        "pattern (old default)": partial(denoise, cloud.points, DenoiseConfig()),
    }
    actions.update(
        {
            str(m): partial(denoise, cloud.points, cfg, cloud.optical_axis)
            for m, cfg in paper.items()
        }
    )
    return actions


LABEL_RULE = "label rule on measured points (knows the true surfaces)"
"""Not a filter: a point is removed where its measured position lies farther than three range-noise
sigmas from every true surface, the label's rule applied to the noisy point instead of the
noise-free one. It shows how far range noise alone blurs the labels: a filter may score above it
(it pools many returns), but where it scores far above a filter, the filter misses what the point
positions themselves show."""
LABEL_SIGMAS = 3.0


def bleeding_table(draws: int, stops: list[int], first: int = 0) -> str:
    """Markdown: per draw (seeds `first`..`first + draws - 1`), P / R / F of each filter; then
    mean and minimum F, seconds per 100k."""
    rows: list[str] = []
    scores: dict[str, list[float]] = defaultdict(list)
    cpu: dict[str, float] = defaultdict(float)
    points = 0
    labels: list[str] = []
    seeds = range(first, first + draws)
    for seed in seeds:
        case = draw_bleeding_case(seed)
        tallies: dict[str, Tally] = defaultdict(Tally)
        bleeding = size = 0
        for beam in bleeding_stop_clouds(case, stops):
            size += len(beam.cloud.points)
            bleeding += int(beam.cloud.is_bleeding.sum())
            nowhere = np.zeros(len(beam.cloud.points), dtype=np.bool_)
            for label, action in draw_filters(beam).items():
                started = time.process_time()
                keep = action().keep
                cpu[label] += time.process_time() - started
                tallies[label].add(keep, beam.cloud, nowhere)
            by_rule = beam.surface_distance_m <= LABEL_SIGMAS * beam.range_noise_m
            tallies[LABEL_RULE].add(by_rule, beam.cloud, nowhere)
        points += size
        labels = list(tallies)
        cells = []
        for label in labels:
            precision, recall, f_score = tallies[label].scores()
            scores[label].append(f_score)
            cells.append(f"{precision:.2f} / {recall:.2f} / **{f_score:.2f}**")
        rows.append(
            f"| {seed} | {case.pattern} | {case.describe()} | {size} | {bleeding} | "
            + " | ".join(cells)
            + " |"
        )
        print(rows[-1], file=sys.stderr, flush=True)
    head = [
        f"## Randomised bleeding models ({draws} draws from {first}, stops {stops}, every LiDAR, "
        "every point judged)\n",
        "| draw | pattern | model | points | bleeding | "
        + " | ".join(f"{m} P / R / F" for m in labels)
        + " |",
        "|---|---|---|---:|---:|" + "---|" * len(labels),
    ]
    summary = [
        "\n| filter | mean F | min F | mean F rosette | mean F spinning | CPU s per 100k |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    patterns = [draw_bleeding_case(seed).pattern for seed in seeds]
    for label in labels:
        f = np.array(scores[label])
        by = {p: f[[q == p for q in patterns]].mean() for p in ("rosette", "spinning")}
        summary.append(
            f"| {label} | {f.mean():.3f} | {f.min():.3f} | {by['rosette']:.3f} | "
            f"{by['spinning']:.3f} | "
            + ("n/a" if label == LABEL_RULE else f"{cpu[label] / points * 1e5:.3f}")
            + " |"
        )
    return "\n".join(head + rows + summary)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--scenes", default=",".join(DEFAULT_SCENES))
    parser.add_argument("--seeds", default="10,11")
    parser.add_argument("--stop-step", type=int, default=2, help="use every n-th stop")
    parser.add_argument("--repeats", type=int, default=5, help="timing runs per method")
    parser.add_argument("--timing-only", action="store_true", help="only the timing table")
    parser.add_argument("--bleeding-draws", type=int, default=0, help="randomised beam models")
    parser.add_argument("--draw-stops", default="0,8", help="stops of each draw's scene")
    parser.add_argument("--first-draw", type=int, default=0, help="seed of the first draw")
    args = parser.parse_args()
    if args.bleeding_draws:
        stops = [int(s) for s in args.draw_stops.split(",") if s]
        print(bleeding_table(args.bleeding_draws, stops, args.first_draw))
        return
    scenes = [s for s in args.scenes.split(",") if s]
    seeds = [int(s) for s in args.seeds.split(",") if s]
    if args.timing_only:
        print(timing_table(scenes, seeds, args.repeats))
        return

    results = {scene: score_scene(scene, seeds, args.stop_step) for scene in scenes}
    labels = list(next(iter(results.values()))[0])
    print(f"## Bleeding-point removal (seeds {seeds}, stops [::{args.stop_step}], all LiDARs)\n")
    print("| scene | points | bleeding | " + " | ".join(f"{m} P / R / F" for m in labels) + " |")
    print("|---|---:|---:|" + "---|" * len(labels))
    for scene, (tallies, points, bleeding) in results.items():
        cells = []
        for label in labels:
            precision, recall, f_score = tallies[label].scores()
            cells.append(f"{precision:.3f} / {recall:.3f} / **{f_score:.3f}**")
        print(f"| {scene} | {points} | {bleeding} | " + " | ".join(cells) + " |")

    print(f"\n## Clean points removed within {CENTRE_DISC_M} m of the observation centre\n")
    print("| scene | clean points there | " + " | ".join(labels) + " |")
    print("|---|---:|" + "---:|" * len(labels))
    for scene, (tallies, _, _) in results.items():
        near = tallies[labels[0]].clean_near_centre
        shares = [tallies[m].clean_near_centre_removed / max(near, 1) for m in labels]
        print(f"| {scene} | {near} | " + " | ".join(f"{s:.1%}" for s in shares) + " |")

    print()
    print(timing_table(scenes, seeds, args.repeats))
    # The same on every core: pykdtree's kNN query is OpenMP-parallel, and OMP_NUM_THREADS is
    # read once per process.
    every_core = subprocess.run(
        [sys.executable, "-m", "tests.bench.bench_denoise", "--timing-only", *sys.argv[1:]],
        env={**os.environ, "OMP_NUM_THREADS": str(os.cpu_count() or 1)},
        check=True,
        capture_output=True,
        text=True,
    )
    print()
    print(every_core.stdout.strip())


if __name__ == "__main__":
    main()
