"""The randomised benchmark (issue 13): calibrate the recordings `fleetcal synth random` draws.

    .venv/bin/python -m tests.bench.bench_random [--seeds 1000-1099] [--jobs 2]
        [--rate-scale 1.0] [--cache /tmp/fleetcal-bench-random] [--methods proposed ...]
        [--worlds open,room,people,uneven-floor,dust,factory,random]
        [--without-checks metric_error,...] [--limits seen_metric_error=0.015,...]

For each seed the recording is synthesised once into `CACHE/recordings/rate-F/seed-N` (a
recording left half-written is written again), then read from disk with `pipeline.io` and
calibrated by each method, as a user's upload would be. Each (method, seed) result is kept in
`CACHE/results/rate-F/METHOD/seed-N.json`, so an interrupted run resumes where it stopped.
Results are kept by method name, not by code: each records the commit it was calibrated at
(`code_version`), and the report warns when one method's results come from several.
Seeds run in `--jobs` processes, each with one BLAS thread. A full-rate recording takes 0.4-0.9
GB: one stays cached only while the cache's disk keeps `--keep-free-gb` free (else it is deleted
once its methods have results, as with `--discard-recordings`), so a long run never fills the disk.

`--worlds W1,W2,...` runs every seed in each world (`random_scenario(seed, world=W)`: the same
robot, routine, objects, errors and clocks; only the world differs), cached per world under
`CACHE/recordings/rate-F/world-W/seed-N` and `CACHE/results/rate-F/world-W/METHOD/seed-N.json`.
The tables then gain the world in the class and a table per world, and a paired table sets each
world against `open` on the same seeds ("with walls against without"): the differences of the
recordings' errors (world - open), and how many recordings each came out better in. Without
`--worlds` the run is the open floor exactly as before the world axis.

Each result keeps every check of its verdict (name, value, limit, outcome) and, per
non-reference LiDAR, its object points' distances to the reference's map as a 1 mm histogram
(`distance_histogram`). `--without-checks KINDS` judges the cached verdicts again without those
kinds of check (`without_checks`): what a verdict without them would have said, in seconds;
`--limits KIND=LIMIT,...` judges them again with other limits (`with_limits`).

The error of a recording is, over its non-reference LiDARs, the largest error of the calibrated
`T_ref_lidar` against the truth (as `bench_calibration` measures it). Success: within 5 mm and
0.1 deg. The verdict's confusion: passed and within 10 mm / 0.3 deg; passed and worse (a
**false pass**); failed and within 5 mm / 0.1 deg (a false fail); failed and worse. A recording
the reader or the pipeline refuses counts as failed and as no success, in its own column.
RMS of error / sigma: per LiDAR, the error over the norm of its reported 1-sigma (1 for an
honest sigma). Seconds: read and calibrate, per recording. A last table per method splits the
recordings by whether every LiDAR's reported 1-sigma is within the success bar
(`determination`): what the data determines, by the pipeline's own estimate.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402
from collections.abc import Callable, Collection, Iterable, Mapping, Sequence  # noqa: E402
from concurrent.futures import ProcessPoolExecutor, as_completed  # noqa: E402
from dataclasses import asdict, dataclass, field, replace  # noqa: E402
from functools import cache  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import TYPE_CHECKING  # noqa: E402

import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from tests.bench.bench_calibration import (  # noqa: E402
    CONFIG_METHODS,
    Trial,
    calibrated_T_ref_lidar,
    calibration_errors,
    method_config,
    paired_table,
    true_T_ref_lidar,
)

if TYPE_CHECKING:
    from pipeline.calibrate import CalibrationResult
    from pipeline.synth.truth import Truth

SUCCESS = (0.005, 0.1)
"""Within this translation (m) and rotation (deg) error a calibration succeeded."""
PASS_OK = (0.010, 0.3)
"""A passed verdict is right within this error, a false pass beyond it."""
PAIRS = (
    ("with_stage1", "without_stage1"),
    ("proposed", "point_to_point"),
    ("proposed", "without_moving_points"),
)
OPEN_WORLD = "open"
TIE = (0.5, 0.01)
"""Error differences (mm, deg) within which a world and the open floor tie on a recording."""


@dataclass
class SeedResult:
    """One method on one seed. Errors and sigmas per non-reference LiDAR (m, deg)."""

    seed: int
    method: str
    scenario_class: str
    clock: str
    translation: list[float] = field(default_factory=list)
    rotation: list[float] = field(default_factory=list)
    sigma_translation: list[float] = field(default_factory=list)
    sigma_rotation: list[float] = field(default_factory=list)
    passed: bool = False
    refused: str | None = None
    seconds: float = 0.0
    world: str = ""
    """The world the recording was made in (`WORLDS`); "" for a run without `--worlds`."""
    metric_error_m: float | None = None
    """Eq. 12 after calibration (what the verdict's `metric_error` check judged)."""
    failed_checks: list[str] = field(default_factory=list)
    """The names of the verdict's failed checks (why a failed verdict failed)."""
    checks: list[dict[str, object]] = field(default_factory=list)
    """Every check of the verdict: name, value, limit, passed (a verdict rule can be judged
    again from these without calibrating again)."""
    distance_histograms: list[list[int]] = field(default_factory=list)
    """Per non-reference LiDAR, its object points' distances to the reference's map after
    calibration in 1 mm bins, the last bin those at eq. 12's cap (`distance_histogram`)."""
    stddev: list[list[float]] = field(default_factory=list)
    """Per non-reference LiDAR its reported 1-sigma per axis: x, y, z (m), roll, pitch, yaw
    (deg), in the level base axes through its origin (what the verdict's checks judge)."""
    T_ref_lidar: list[list[list[float]]] = field(default_factory=list)
    """The calibrated poses of every LiDAR in the reference's frame (reference first): two
    methods' solutions compared on a seed without calibrating again."""
    code: str = ""
    """The code the result was calibrated with (`code_version`); "" in results cached before
    it was recorded, or outside a git checkout."""
    along_reference_axis: list[float] = field(default_factory=list)
    """Per non-reference LiDAR, its translation error (m, estimate - truth of `T_ref_lidar`)
    along the reference's optical axis; empty in results cached before it was recorded."""
    reference_model: str = ""
    """The reference LiDAR's model (`livox-mid70`, ...): its optical axis means a direction of
    view only for a head that looks one way."""

    @property
    def max_translation(self) -> float:
        return max(self.translation) if self.translation else float("inf")

    @property
    def max_rotation(self) -> float:
        return max(self.rotation) if self.rotation else float("inf")

    def within(self, limits: tuple[float, float]) -> bool:
        return self.refused is None and (
            self.max_translation <= limits[0] and self.max_rotation <= limits[1]
        )


def parse_seeds(text: str) -> list[int]:
    """`1000-1099`, `7` or `1,5,9-11` -> the seeds."""
    seeds: list[int] = []
    for part in text.split(","):
        low, _, high = part.strip().partition("-")
        try:
            first, last = int(low), int(high or low)
        except ValueError:
            raise SystemExit(f"--seeds {text!r}: write seeds as 1000-1099, 7 or 1,5,9-11") from None
        if last < first:
            raise SystemExit(f"--seeds {text!r}: a range runs from low to high, e.g. 1000-1099")
        seeds += range(first, last + 1)
    return seeds


# -- one seed (in a worker process) -----------------------------------------------------------


def _rate_dir(kind: str, cache: Path, rate_scale: float, world: str | None) -> Path:
    """`CACHE/KIND/rate-F`, and `world-W` under it for a run in a given world."""
    out = cache / kind / f"rate-{rate_scale:g}"
    return out if world is None else out / f"world-{world}"


def recording_dir(cache: Path, rate_scale: float, seed: int, world: str | None = None) -> Path:
    return _rate_dir("recordings", cache, rate_scale, world) / f"seed-{seed}"


def result_path(
    cache: Path, rate_scale: float, method: str, seed: int, world: str | None = None
) -> Path:
    return _rate_dir("results", cache, rate_scale, world) / method / f"seed-{seed}.json"


def ensure_recording(
    cache: Path, rate_scale: float, seed: int, world: str | None = None
) -> tuple[Path, float]:
    """The seed's recording directory (in `world`), synthesised unless a complete one is cached;
    and the seconds synthesis took (0 when cached)."""
    from pipeline.synth.random_scenario import random_scenario
    from pipeline.synth.recording import write_recording
    from pipeline.synth.truth import TRUTH_FILE

    out = recording_dir(cache, rate_scale, seed, world)
    if (out / TRUTH_FILE).is_file():  # written last: its presence means the bag is complete
        return out, 0.0
    if out.exists():
        shutil.rmtree(out)
    started = time.perf_counter()
    spec = random_scenario(seed, world=world)
    write_recording(spec, out, seed=seed, rate_scale=rate_scale)
    return out, time.perf_counter() - started


def run_seed(
    cache: Path,
    rate_scale: float,
    seed: int,
    methods: Sequence[str],
    world: str | None = None,
    discard_recording: bool = False,
    keep_free_bytes: int = 0,
) -> list[SeedResult]:
    """Synthesise (once) and calibrate one seed (in `world`) with each method not already
    cached; with `discard_recording`, or when the cache's disk has less than `keep_free_bytes`
    free, delete the recording once every method has its result."""
    from pipeline.calibrate import calibrate
    from pipeline.errors import PipelineError
    from pipeline.io import read_recording
    from pipeline.synth.random_scenario import clock_kind, random_scenario, world_name
    from pipeline.synth.truth import load_truth

    spec = random_scenario(seed, world=world)
    results = []
    paths = {m: result_path(cache, rate_scale, m, seed, world) for m in methods}
    todo = [m for m in methods if not paths[m].is_file()]
    directory = recording_dir(cache, rate_scale, seed, world)
    if todo:
        directory, _ = ensure_recording(cache, rate_scale, seed, world)
    for method in methods:
        path = paths[method]
        if method not in todo:
            results.append(SeedResult(**json.loads(path.read_text())))
            continue
        record = SeedResult(seed, method, spec.scenario_class, clock_kind(spec))
        record.world = world_name(spec) if world is not None else ""
        record.code = code_version()
        started = time.perf_counter()
        try:
            config = method_config(method)
            problem = read_recording(directory / "recording", config.reader)
            result = calibrate(problem, config)
        except PipelineError as err:
            record.refused = f"{type(err).__name__}: {err}"
        else:
            truth = load_truth(directory)
            t, r, sigma_t, sigma_r = calibration_errors(result, truth)
            record.along_reference_axis = along_reference_axis(result, truth)
            record.reference_model = next(
                x.model for x in truth.lidars if x.frame == result.lidars[0].frame
            )
            record.translation, record.rotation = t, r
            record.sigma_translation, record.sigma_rotation = sigma_t, sigma_r
            record.T_ref_lidar = calibrated_T_ref_lidar(result).tolist()
            record.stddev = [
                [*x.uncertainty.stddev_translation_m, *x.uncertainty.stddev_rotation_deg]
                for x in result.lidars[1:]
            ]
            record.passed = bool(result.passed)
            record.metric_error_m = result.metric_error_final
            record.failed_checks = [check.name for check in result.verdict.failed]
            record.checks = [
                {"name": c.name, "value": c.value, "limit": c.limit, "passed": c.passed}
                for c in result.verdict.checks
            ]
            record.distance_histograms = [
                distance_histogram(d, config.metric.max_distance_m)
                for d in result.object_distances_final_m[1:]
            ]
        record.seconds = time.perf_counter() - started
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_suffix(".partial")
        partial.write_text(json.dumps(asdict(record)))
        partial.replace(path)  # atomic: a killed run leaves no half-written result
        results.append(record)
    if directory.exists() and (
        discard_recording or shutil.disk_usage(directory).free < keep_free_bytes
    ):
        shutil.rmtree(directory)
    return results


def along_reference_axis(result: CalibrationResult, truth: Truth) -> list[float]:
    """Per non-reference LiDAR of `result`, the translation error of its `T_ref_lidar` (m,
    estimate - truth, in the reference's frame) along the reference's optical axis.

    A range bias of the reference's surfaces (behind or in front of the true ones along its
    beams) moves every other LiDAR the same way along the reference's view: the mean of this
    over recordings whose reference looks one way shows such a bias, where errors of either
    sign from chance average out."""
    frames = [x.frame for x in result.lidars]
    axis = next(x.optical_axis for x in truth.lidars if x.frame == frames[0])
    error = calibrated_T_ref_lidar(result)[1:, :3, 3] - true_T_ref_lidar(truth, frames)[1:, :3, 3]
    return [float(e) for e in error @ (axis / np.linalg.norm(axis))]


def distance_histogram(capped: NDArray[np.float64], cap_m: float) -> list[int]:
    """Counts of `capped` distances (m) in 1 mm bins below `cap_m`, then one bin of those at the
    cap."""
    bins = round(cap_m * 1000)
    index = np.minimum(np.floor(np.asarray(capped) * 1000).astype(np.int64), bins)
    return [int(c) for c in np.bincount(index, minlength=bins + 1)]


def _require_checks(record: SeedResult) -> None:
    if not record.checks:
        raise SystemExit(
            f"seed {record.seed} ({record.method}): its cached result keeps no checks; delete "
            "it (or use a new --cache) to calibrate it again before judging it again"
        )


def without_checks(record: SeedResult, kinds: Collection[str]) -> SeedResult:
    """`record` judged again as if the verdict had no checks of these kinds (a check's kind is
    its name before `:`, e.g. `metric_error`, `convergence`): passed when every other check
    passed. A refusal stays one; a result cached before the checks were kept cannot be judged
    again."""
    if record.refused is not None or not kinds:
        return record
    _require_checks(record)
    kept = [c for c in record.checks if str(c["name"]).split(":")[0] not in kinds]
    return replace(
        record,
        passed=all(bool(c["passed"]) for c in kept),
        failed_checks=[str(c["name"]) for c in kept if not c["passed"]],
    )


def with_limits(record: SeedResult, limits: Mapping[str, float]) -> SeedResult:
    """`record` judged again with these limits for the checks of these kinds (at-most checks:
    a check passes when its value is finite and at most its limit). `metric_error` (eq. 12, not
    checked by default) is judged from the recording's eq. 12 where its verdict had no such check.
    A refusal stays one."""
    if record.refused is not None or not limits:
        return record
    _require_checks(record)
    checks = [dict(c) for c in record.checks]
    if "metric_error" in limits and not any(c["name"] == "metric_error" for c in checks):
        checks.insert(0, {"name": "metric_error", "value": record.metric_error_m})
    for check in checks:
        limit = limits.get(str(check["name"]).split(":")[0])
        if limit is not None:
            value = check["value"]
            passed = isinstance(value, int | float) and math.isfinite(value) and value <= limit
            check.update(limit=limit, passed=passed)
    return replace(
        record,
        checks=checks,
        passed=all(bool(c["passed"]) for c in checks),
        failed_checks=[str(c["name"]) for c in checks if not c["passed"]],
    )


def parse_limits(text: str) -> dict[str, float]:
    """`kind=limit,...` (e.g. `seen_metric_error=0.015,metric_error=0.04`) as a mapping."""
    limits = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        kind, _, value = item.partition("=")
        try:
            limits[kind.strip()] = float(value)
        except ValueError:
            raise SystemExit(f"--limits: {item!r} is not kind=number") from None
    return limits


@cache
def code_version() -> str:
    """This checkout's commit, `-dirty` when it has uncommitted changes (`git describe --always
    --dirty`); "" where git cannot tell."""
    try:
        done = subprocess.run(
            ["git", "describe", "--always", "--dirty"],
            cwd=Path(__file__).resolve().parents[2],
            capture_output=True,
            text=True,
            check=True,
        )
    except (OSError, subprocess.CalledProcessError):
        return ""
    return done.stdout.strip()


def mixed_code(records: Iterable[SeedResult]) -> list[str]:
    """One warning per method whose results come from more than one code version (a cache
    keeps a method's results by name: a run after a change reads the older ones back)."""
    versions: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for record in records:
        versions[record.method][record.code or "unknown"] += 1
    return [
        f"{method}'s results come from {len(counts)} code versions: "
        + ", ".join(f"{code} ({n})" for code, n in sorted(counts.items()))
        + f"; delete the cache's results/{method} to calibrate them again with this code"
        for method, counts in sorted(versions.items())
        if len(counts) > 1
    ]


def describe(record: SeedResult) -> str:
    if record.refused:
        return f"refused ({record.refused[:120]})"
    verdict = "passed" if record.passed else "failed"
    return (
        f"{1000 * record.max_translation:.1f} mm / {record.max_rotation:.3f} deg, {verdict} "
        f"({record.seconds:.0f} s)"
    )


# -- tables ----------------------------------------------------------------------------------


def _percentile(values: Sequence[float], q: float) -> float:
    return float(np.percentile(values, q)) if len(values) else float("nan")


def summary_row(label: str, records: Sequence[SeedResult]) -> str:
    """One row of the accuracy table for `records` (one method)."""
    n = len(records)
    calibrated = [r for r in records if r.refused is None]
    t = [1000 * v for r in calibrated for v in r.translation]
    rot = [v for r in calibrated for v in r.rotation]
    success = sum(r.within(SUCCESS) for r in records)
    passed_ok = sum(r.passed and r.within(PASS_OK) for r in calibrated)
    false_pass = sum(r.passed and not r.within(PASS_OK) for r in calibrated)
    false_fail = sum(not r.passed and r.within(SUCCESS) for r in calibrated)
    failed_worse = sum(not r.passed and not r.within(SUCCESS) for r in calibrated)
    refused = n - len(calibrated)
    ratio_t = [
        e / max(s, 1e-12)
        for r in calibrated
        for e, s in zip(r.translation, r.sigma_translation, strict=False)
    ]
    ratio_r = [
        e / max(s, 1e-12)
        for r in calibrated
        for e, s in zip(r.rotation, r.sigma_rotation, strict=False)
    ]

    def stats(values: Sequence[float], digits: int) -> str:
        if not values:
            return "n/a | n/a | n/a | n/a"
        return " | ".join(
            f"{x:.{digits}f}"
            for x in (np.mean(values), np.median(values), _percentile(values, 95), np.max(values))
        )

    def rms(values: Sequence[float]) -> str:
        return f"{np.sqrt(np.mean(np.square(values))):.2f}" if values else "n/a"

    seconds = np.mean([r.seconds for r in records]) if records else float("nan")
    return (
        f"| {label} | {n} | {success}/{n} ({100 * success / max(n, 1):.0f} %) "
        f"| {stats(t, 2)} | {stats(rot, 3)} "
        f"| {passed_ok} | **{false_pass}** | {false_fail} | {failed_worse} | {refused} "
        f"| {rms(ratio_t)} / {rms(ratio_r)} | {seconds:.1f} |"
    )


TABLE_HEADER = (
    "| {group} | recordings | success (<= 5 mm, 0.1 deg) "
    "| mean t (mm) | median t | p95 t | max t "
    "| mean r (deg) | median r | p95 r | max r "
    "| passed, within 10 mm / 0.3 deg | false pass | false fail | failed, worse | refused "
    "| RMS error/sigma t / r | seconds |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
)


def grouped_table(
    records: Iterable[SeedResult], key: Callable[[SeedResult], str], group: str
) -> str:
    """Rows per value of `key` (sorted), then one row over all."""
    groups: dict[str, list[SeedResult]] = defaultdict(list)
    everything = list(records)
    for record in everything:
        groups[key(record)].append(record)
    rows = [summary_row(name, groups[name]) for name in sorted(groups)]
    rows.append(summary_row("**all**", everything))
    return "\n".join([TABLE_HEADER.format(group=group), *rows])


def comparisons(methods: Sequence[str]) -> list[tuple[str, str]]:
    """The (method, baseline) pairs of `methods` to compare recording by recording: `PAIRS`,
    and every other method against `proposed` (the default)."""
    pairs = [(m, b) for m, b in PAIRS if m in methods and b in methods]
    paired = {name for pair in PAIRS for name in pair if "proposed" in pair}
    if "proposed" in methods:
        pairs += [(m, "proposed") for m in methods if m != "proposed" and m not in paired]
    return pairs


def report(records: Sequence[SeedResult], methods: Sequence[str]) -> str:
    """The markdown report: per method, by class and by each axis of the class (the world where
    the records have one) and the clock; then the pairs of methods, and of worlds against the
    open floor."""
    out: list[str] = []
    axes = ["routine", "sensors", "errors"]
    worlds = any(r.world for r in records)
    if worlds:
        axes.append("world")
    for method in methods:
        mine = [r for r in records if r.method == method]
        out.append(f"## {method}: per scenario class\n")
        out.append(grouped_table(mine, lambda r: r.scenario_class, "class"))
        for index, axis in enumerate(axes):
            out.append(f"\n## {method}: per {axis}\n")
            out.append(grouped_table(mine, class_axis(index), axis))
        out.append(f"\n## {method}: per header clock\n")
        out.append(grouped_table(mine, lambda r: r.clock, "clock"))
        out.append(f"\n## {method}: by what the data determines (the reported 1-sigma)\n")
        out.append(grouped_table(mine, determination, "reported 1-sigma"))
        out.append(f"\n## {method}: error along the reference's optical axis, by its model\n")
        out.append(axis_bias_table(mine))
        out.append("")
    for method, baseline in comparisons(methods):
        out.append(f"## {method} against {baseline}, recording by recording\n")
        out.append(paired_table(as_trials(records), method, baseline))
        out.append("")
    if worlds:
        for method in methods:
            out.append(f"## {method}: each world against the open floor, on the same seeds\n")
            out.append(world_pairs_table([r for r in records if r.method == method]))
            out.append("")
    return "\n".join(out)


def axis_bias_row(label: str, records: Sequence[SeedResult]) -> str:
    """Recordings, LiDARs, and the signed error along the reference's optical axis (mm): the
    mean over recordings of each recording's mean over its LiDARs (its LiDARs share one
    reference map, so they are not independent) with its standard error, the median over
    LiDARs, and the share of recordings whose mean is positive."""
    means = [1000 * float(np.mean(r.along_reference_axis)) for r in records]
    lidars = [1000 * v for r in records for v in r.along_reference_axis]
    n = len(means)
    if n == 0:
        return f"| {label} | 0 | 0 | n/a | n/a | n/a | n/a |"
    stderr = f"{np.std(means, ddof=1) / math.sqrt(n):.2f}" if n > 1 else "n/a"
    positive = sum(m > 0 for m in means)
    return (
        f"| {label} | {n} | {len(lidars)} | {np.mean(means):+.2f} | {stderr} "
        f"| {np.median(lidars):+.2f} | {positive}/{n} |"
    )


def axis_bias_table(records: Iterable[SeedResult]) -> str:
    """`axis_bias_row` per reference model, then over all, of the recordings within
    `PASS_OK` (a wrong basin, metres off, says nothing of a millimetre bias) that recorded the
    error along the axis (results cached before it was recorded are left out)."""
    measured = [r for r in records if r.within(PASS_OK) and r.along_reference_axis]
    groups: dict[str, list[SeedResult]] = defaultdict(list)
    for record in measured:
        groups[record.reference_model].append(record)
    header = (
        "| reference | recordings | LiDARs | mean error along its axis (mm) | standard error "
        "| median over LiDARs | recordings positive |\n|---|---|---|---|---|---|---|"
    )
    rows = [axis_bias_row(model, groups[model]) for model in sorted(groups)]
    return "\n".join([header, *rows, axis_bias_row("**all**", measured)])


DETERMINED = f"every 1-sigma within {1000 * SUCCESS[0]:g} mm / {SUCCESS[1]:g} deg"
UNDETERMINED = f"a 1-sigma above {1000 * SUCCESS[0]:g} mm or {SUCCESS[1]:g} deg"


def determination(record: SeedResult) -> str:
    """Whether the pipeline reports every LiDAR of `record` determined to the success bar: each
    axis's 1-sigma (`stddev`: x, y, z in m, then roll, pitch, yaw in deg) within `SUCCESS`, the
    limits the verdict's uncertainty checks also apply. A recording whose data leaves a LiDAR
    less certain than the bar can be within it only by luck; the table by this key says how
    many draws are of that kind, and how the others do (it reads the reported sigma, so it is
    only as honest as the RMS of error over sigma says)."""
    if record.refused is not None:
        return "refused"
    worst_m = max((max(axes[:3]) for axes in record.stddev), default=0.0)
    worst_deg = max((max(axes[3:]) for axes in record.stddev), default=0.0)
    return DETERMINED if worst_m <= SUCCESS[0] and worst_deg <= SUCCESS[1] else UNDETERMINED


def class_axis(index: int) -> Callable[[SeedResult], str]:
    """A record's `index`-th axis of its class (routine, sensors, errors, world)."""
    return lambda record: record.scenario_class.split("/")[index]


@dataclass(frozen=True)
class WorldPair:
    """One seed in a world and on the open floor (one method)."""

    world: SeedResult
    open: SeedResult


def world_pairs(records: Iterable[SeedResult]) -> dict[str, list[WorldPair]]:
    """Per world other than open (sorted): its records paired with the open floor's of the same
    seed and method, by seed. A seed missing on either side makes no pair."""
    everything = list(records)
    opens = {(r.seed, r.method): r for r in everything if r.world == OPEN_WORLD}
    pairs: dict[str, list[WorldPair]] = defaultdict(list)
    for r in sorted(everything, key=lambda r: (r.world, r.seed, r.method)):
        if r.world not in ("", OPEN_WORLD) and (r.seed, r.method) in opens:
            pairs[r.world].append(WorldPair(r, opens[(r.seed, r.method)]))
    return dict(pairs)


def world_pairs_row(label: str, pairs: Sequence[WorldPair]) -> str:
    """Successes on each side; over the pairs both calibrated, the differences of the
    recordings' errors (world - open: negative, the world is more accurate) and how many the
    world won, tied (`TIE`) and lost, in translation and rotation; pairs one side refused."""
    n = len(pairs)
    success_world = sum(p.world.within(SUCCESS) for p in pairs)
    success_open = sum(p.open.within(SUCCESS) for p in pairs)
    both = [p for p in pairs if p.world.refused is None and p.open.refused is None]
    dt = np.array([1000 * (p.world.max_translation - p.open.max_translation) for p in both])
    dr = np.array([p.world.max_rotation - p.open.max_rotation for p in both])

    def stats(values: NDArray[np.float64], digits: int) -> str:
        if not len(values):
            return "n/a | n/a | n/a"
        return " | ".join(
            f"{x:+.{digits}f}" for x in (values.mean(), np.median(values), values.max())
        )

    def record(values: NDArray[np.float64], tie: float) -> str:
        won, lost = int((values < -tie).sum()), int((values > tie).sum())
        return f"{won} / {len(values) - won - lost} / {lost}"

    refused = (
        f"{sum(p.world.refused is not None for p in pairs)} / "
        f"{sum(p.open.refused is not None for p in pairs)}"
    )
    return (
        f"| {label} | {n} | {success_world}/{n} | {success_open}/{n} "
        f"| {stats(dt, 2)} | {stats(dr, 3)} "
        f"| {record(dt, TIE[0])} | {record(dr, TIE[1])} | {refused} |"
    )


def world_pairs_table(records: Iterable[SeedResult]) -> str:
    """A row per world against the open floor (one method's `records`), then all of them."""
    pairs = world_pairs(records)
    lines = [
        "| world | pairs | success in world | success open "
        "| mean dt (mm, world - open) | median dt | max dt "
        "| mean dr (deg) | median dr | max dr "
        f"| t won / tied / lost (tie: {TIE[0]:g} mm) | r won / tied / lost ({TIE[1]:g} deg) "
        "| refused: world / open |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    lines += [world_pairs_row(world, pairs[world]) for world in pairs]
    lines.append(world_pairs_row("**all**", [p for world in pairs for p in pairs[world]]))
    return "\n".join(lines)


def as_trials(records: Iterable[SeedResult]) -> dict[str, list[dict[str, Trial]]]:
    """`bench_calibration`'s layout (class -> per recording -> method -> Trial), refusals left
    out; a recording is a seed in a world."""
    by_seed: dict[tuple[int, str], dict[str, Trial]] = defaultdict(dict)
    classes: dict[tuple[int, str], str] = {}
    for r in records:
        if r.refused is None:
            key = (r.seed, r.world)
            by_seed[key][r.method] = Trial(r.translation, r.rotation, r.seconds, passed=r.passed)
            classes[key] = r.scenario_class
    grouped: dict[str, list[dict[str, Trial]]] = defaultdict(list)
    for seed in sorted(by_seed):
        grouped[classes[seed]].append(by_seed[seed])
    return dict(sorted(grouped.items()))


# -- main ------------------------------------------------------------------------------------


def parse_worlds(text: str | None) -> list[str | None]:
    """`open,room` -> the worlds to run each seed in; None -> [None], the run without worlds."""
    from pipeline.synth.random_scenario import RANDOM_WORLD, WORLDS

    if text is None:
        return [None]
    worlds = [part.strip() for part in text.split(",") if part.strip()]
    unknown = [w for w in worlds if w not in (*WORLDS, RANDOM_WORLD)]
    if unknown or not worlds or len(set(worlds)) != len(worlds):
        raise SystemExit(
            f"--worlds {text!r}: name each world once, from {', '.join(WORLDS)} and "
            f"{RANDOM_WORLD}, e.g. --worlds open,room (open is what the others are paired with)"
        )
    return list(worlds)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--seeds", default="1000-1099", help="e.g. 1000-1099, 7 or 1,5,9-11")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes")
    parser.add_argument("--rate-scale", type=float, default=1.0, help="LiDAR point rate (1: full)")
    parser.add_argument("--cache", type=Path, default=Path("/tmp/fleetcal-bench-random"))
    parser.add_argument("--methods", nargs="*", default=["proposed"], choices=list(CONFIG_METHODS))
    parser.add_argument(
        "--worlds",
        "--world",
        help="run each seed in these worlds, e.g. open,room,people,uneven-floor,dust,factory "
        "(random: the seed draws one); left out: the open floor, as before worlds existed",
    )
    parser.add_argument(
        "--discard-recordings",
        action="store_true",
        help="delete each seed's recording once all its methods have results (a full-rate "
        "recording takes 0.4-0.9 GB; the results stay cached, a later method synthesises again)",
    )
    parser.add_argument(
        "--keep-free-gb",
        type=float,
        default=20.0,
        help="keep a recording in the cache only while its disk has this much free space, so a "
        "long run cannot fill the disk (100 full-rate recordings take about 60 GB)",
    )
    parser.add_argument(
        "--without-checks",
        default="",
        help="judge the verdicts again without these check kinds, e.g. metric_error (comma "
        "separated; from the cached checks, nothing is calibrated again): what a verdict "
        "without them would have said",
    )
    parser.add_argument(
        "--limits",
        default="",
        help="judge the verdicts again with these limits, e.g. seen_metric_error=0.015 or "
        "metric_error=0.04 (comma separated kind=limit; from the cached checks)",
    )
    args = parser.parse_args(argv)
    seeds = parse_seeds(args.seeds)
    limits = parse_limits(args.limits)
    dropped = {kind.strip() for kind in args.without_checks.split(",") if kind.strip()}
    worlds = parse_worlds(args.worlds)
    if args.jobs < 1 or not args.rate_scale > 0:
        raise SystemExit("--jobs must be 1 or more and --rate-scale positive")
    print(
        f"bench_random: {len(seeds)} seeds, rate x{args.rate_scale:g}, {args.jobs} jobs, "
        f"methods {', '.join(args.methods)}, cache {args.cache}"
        + (f", worlds {args.worlds}" if args.worlds else ""),
        file=sys.stderr,
        flush=True,
    )
    records: list[SeedResult] = []
    started = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futures = {
            pool.submit(
                run_seed,
                args.cache,
                args.rate_scale,
                seed,
                args.methods,
                world,
                args.discard_recordings,
                int(args.keep_free_gb * 1e9),
            ): seed
            for seed in seeds
            for world in worlds
        }
        for done, future in enumerate(as_completed(futures), start=1):
            results = future.result()
            records += results
            summary = "; ".join(f"{r.method} {describe(r)}" for r in results)
            print(
                f"[{done}/{len(futures)}, {time.perf_counter() - started:.0f} s] seed "
                f"{futures[future]} {results[0].scenario_class} ({results[0].clock}): {summary}",
                file=sys.stderr,
                flush=True,
            )
    records = sorted(
        (without_checks(with_limits(r, limits), dropped) for r in records),
        key=lambda r: (r.method, r.world, r.seed),
    )
    print(
        f"# bench_random: seeds {args.seeds}, rate scale {args.rate_scale:g}"
        + (f", worlds {args.worlds}" if args.worlds else "")
        + (f", verdicts judged without {', '.join(sorted(dropped))}" if dropped else "")
        + (f", verdicts judged with limits {args.limits}" if limits else "")
        + "\n"
    )
    for warning in mixed_code(records):
        print(f"**Warning**: {warning}.\n")
        print(f"bench_random: {warning}", file=sys.stderr)
    print(report(records, args.methods))


if __name__ == "__main__":
    main()
