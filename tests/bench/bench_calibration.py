"""Accuracy, convergence, stage times and peak memory of the calibration (issue 3's protocol).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m tests.bench.bench_calibration [--quick]
        [--seeds 10] [--first-seed 0] [--rate 1.0] [--cases set1-box ...]
        [--methods proposed ...]
        [--no-timing] [--plot bench-out/convergence.png] [--recordings DIR]

Accuracy: for every case and seed, `simulate_problem(case, seed, rate)` (initial extrinsics
perturbed by up to 0.2 m / 5 deg, odometry by up to 0.2 m / 3 deg, as in the paper) is calibrated
by each method; the error of each non-reference LiDAR relative to the reference (translation m,
rotation deg) is compared with the synthesiser's truth. Methods: `proposed` (the pipeline as
configured by default), `point_to_point` (the same with the paper's point-to-point residual),
`with_stage1` / `without_stage1` (the same with the noise filter switched on / off),
`without_moving_points` (the same without removing the points that move within a stop; not run
by default),
`labelled_stage1` (stage 1 off, the synthesiser's labelled bleeding points removed instead: the
best any noise filter could do),
`without_rr` (no rough refinement, no floor terms), `entire_cloud` (the same optimiser on every
point, no segmentation). `initial` is the error before calibration.

Convergence: mean translation / rotation error per stage-4 iteration over the set-1 trials (a
table and a PNG). Timing: full-rate set-1 (and set-2) recordings are written once, then each goes
file -> result.json in a fresh process (read, all stages, JSON): wall and CPU seconds, peak RSS.
The machine's load average is printed beside the timings: wall time on a shared machine is
blurred by other work, CPU time much less.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import TYPE_CHECKING  # noqa: E402

import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from pipeline.config import PipelineConfig  # noqa: E402
from pipeline.moving_points import scan_ids  # noqa: E402
from pipeline.problem import CalibrationProblem, Stop  # noqa: E402
from pipeline.synth.truth import Truth  # noqa: E402

if TYPE_CHECKING:
    from pipeline.calibrate import CalibrationResult

CASES = (
    "set1-box",
    "set1-cylinder",
    "set1-capsule",
    "set2-box",
    "set2-cylinder",
    "set2-capsule",
    "spinning",
    "driven",
)
METHODS = (
    "proposed",
    "point_to_point",
    "with_stage1",
    "without_stage1",
    "labelled_stage1",
    "without_rr",
    "entire_cloud",
)


@dataclass
class Trial:
    """Errors of one method on one (case, seed): per non-reference LiDAR (m, deg)."""

    translation: list[float] = field(default_factory=list)
    rotation: list[float] = field(default_factory=list)
    seconds: float = 0.0
    iterations: int = 0
    converged: bool = True
    passed: bool | None = None
    history_translation: list[float] = field(default_factory=list)
    history_rotation: list[float] = field(default_factory=list)
    stages: dict[str, float] = field(default_factory=dict)
    stddev_translation: list[float] = field(default_factory=list)
    """Per non-reference LiDAR: the norm of the reported 1-sigma (m, deg), when reported."""
    stddev_rotation: list[float] = field(default_factory=list)


def _errors(
    estimate: NDArray[np.float64], truth: NDArray[np.float64]
) -> tuple[list[float], list[float]]:
    """Per non-reference LiDAR: `estimate`, `truth` (L, 4, 4) are T_ref_lidar, reference first."""
    from pipeline.transforms import pose_difference

    pairs = [pose_difference(truth[i], estimate[i]) for i in range(1, len(truth))]
    return [p[0] for p in pairs], [p[1] for p in pairs]


def true_T_ref_lidar(truth: Truth, frames: Sequence[str]) -> NDArray[np.float64]:
    """(L, 4, 4) true `T_ref_lidar` of `frames`, the reference (`frames[0]`) first."""
    from pipeline.transforms import invert

    true = {lidar.frame: lidar.T_base_lidar_true for lidar in truth.lidars}
    return np.stack([invert(true[frames[0]]) @ true[f] for f in frames])


def calibrated_T_ref_lidar(result: CalibrationResult) -> NDArray[np.float64]:
    """(L, 4, 4) each LiDAR's calibrated pose in the reference LiDAR's frame (reference first)."""
    from pipeline.transforms import invert

    reference = result.lidars[0].T_base_lidar_calibrated
    return np.stack([invert(reference) @ x.T_base_lidar_calibrated for x in result.lidars])


def calibration_errors(
    result: CalibrationResult, truth: Truth
) -> tuple[list[float], list[float], list[float], list[float]]:
    """Per non-reference LiDAR of `result`, relative to its reference: the error of the
    calibrated `T_ref_lidar` against the truth (m, deg) and the norm of the reported 1-sigma
    (m, deg)."""
    estimate = calibrated_T_ref_lidar(result)
    t, r = _errors(estimate, true_T_ref_lidar(truth, [x.frame for x in result.lidars]))
    sigma_t = [float(np.linalg.norm(x.uncertainty.stddev_translation_m)) for x in result.lidars[1:]]
    sigma_r = [float(np.linalg.norm(x.uncertainty.stddev_rotation_deg)) for x in result.lidars[1:]]
    return t, r, sigma_t, sigma_r


CONFIG_METHODS = (
    "proposed",
    "point_to_point",
    "with_stage1",
    "without_stage1",
    "without_moving_points",
    "range_bias_estimated",
    "quadric",
    "surface_k30",
    "surface_k120",
    "surface_k160",
    "surface_noise",
    "beam_fit",
    "fine_cauchy",
    "every_lidar",
    "reference_pairs",
    "floor_measured",
    "extrinsic_convergence",
    "stop_prior",
    "pair_weights",
    "global_alignment",
    "kernel_30mm",
    "kernel_sigmas",
    "surface_debias",
    "global_refined",
    "without_global_alignment",
    "surface_passes2",
    "surface_passes4",
    "surface_sensitivity",
    "without_model_sensitivity",
    "floor_points",
    "anderson",
    "plain_iteration",
    "stage1_spinning",
    "blocks_2m",
)
"""Methods that are the pipeline with another configuration."""


def method_config(method: str) -> PipelineConfig:
    """The configuration of one of `CONFIG_METHODS`."""
    from pipeline.config import config_from_mapping, resolved

    data = resolved(PipelineConfig())
    if method == "point_to_point":
        data["optimisation"]["residual"] = "point_to_point"
    elif method in ("with_stage1", "without_stage1"):
        data["denoise"]["enabled"] = method == "with_stage1"
    elif method == "without_moving_points":
        data["moving_points"]["enabled"] = False
    elif method == "range_bias_estimated":
        data["observability"]["range_bias"] = "estimated"
    elif method == "quadric":
        data["segmentation"]["surface_model"] = "quadric"
    elif method == "beam_fit":
        data["segmentation"]["surface_model"] = "beam_fit"
    elif method == "floor_points":
        data["segmentation"]["floor_fit"] = "points"
    elif method in ("surface_k30", "surface_k120", "surface_k160"):
        data["segmentation"]["surface_neighbours"] = int(method.removeprefix("surface_k"))
    elif method == "surface_noise":
        data["segmentation"]["surface_patch"] = "noise"
    elif method in ("surface_passes2", "surface_passes4"):
        data["segmentation"]["surface_passes"] = int(method[-1])
    elif method == "global_alignment":
        data["global_alignment"]["enabled"] = True
        data["global_alignment"]["choose"] = "score"
    elif method == "without_global_alignment":
        data["global_alignment"]["enabled"] = False
    elif method == "kernel_30mm":
        data["optimisation"]["kernel_scale_min_m"] = 0.03
    elif method == "kernel_sigmas":
        data["optimisation"]["kernel_scale_min_sigmas"] = 3.8
    elif method == "global_refined":
        data["global_alignment"]["enabled"] = True
        data["global_alignment"]["choose"] = "refined"
    elif method == "surface_debias":
        data["segmentation"]["surface_debias"] = "bootstrap"
    elif method == "surface_sensitivity":
        data["observability"]["surface_sensitivity_passes"] = 4
    elif method == "without_model_sensitivity":
        data["observability"]["surface_sensitivity_model"] = None
    elif method == "fine_cauchy":
        data["optimisation"]["fine_robust_loss"] = "cauchy"
    elif method in ("every_lidar", "reference_pairs"):
        data["optimisation"]["cross_pairs"] = method.removesuffix("_pairs")
    elif method == "extrinsic_convergence":
        data["optimisation"].update(
            converge_on="extrinsics",
            stop_prior_sigma_m=1.0,
            translation_tolerance_m=1e-5,
            rotation_tolerance_deg=1e-4,
        )
    elif method == "anderson":
        data["optimisation"]["acceleration"] = "anderson"
    elif method == "plain_iteration":
        data["optimisation"]["acceleration"] = "none"
    elif method == "blocks_2m":
        data["optimisation"]["uncertainty_block_m"] = 2.0
    elif method == "stage1_spinning":
        data["denoise"]["filtered_patterns"] = ["non_repetitive", "repetitive"]
    elif method == "pair_weights":
        data["optimisation"]["pair_weights"] = "lidar_pairs"
    elif method == "stop_prior":
        data["optimisation"]["stop_prior_sigma_m"] = 1.0
    elif method == "floor_measured":
        data["optimisation"]["floor_normal_sigma_deg"] = None
        data["optimisation"]["floor_offset_sigma_m"] = None
    elif method != "proposed":
        raise SystemExit(f"unknown method {method!r}; choose from {CONFIG_METHODS}")
    return config_from_mapping(data)


def _history(
    per_iteration: NDArray[np.float64], truth: NDArray[np.float64]
) -> tuple[list[float], list[float]]:
    """Mean error over the non-reference LiDARs at each iteration; (K, L, 4, 4) in."""
    translation, rotation = [], []
    for T in per_iteration:
        t, r = _errors(T, truth)
        translation.append(float(np.mean(t)))
        rotation.append(float(np.mean(r)))
    return translation, rotation


def without_bleeding(problem: CalibrationProblem, truth: Truth) -> CalibrationProblem:
    """`problem` with the points the synthesiser labelled as bleeding removed from every cloud
    (and from the counts of points per scan)."""

    def kept(stop: Stop, frame: str) -> NDArray[np.bool_]:
        return ~truth.stop_labels(stop.index, frame).is_bleeding

    def sizes(stop: Stop, frame: str) -> tuple[int, ...]:
        scan = scan_ids(stop.scan_sizes[frame])
        counts = np.bincount(scan[kept(stop, frame)], minlength=len(stop.scan_sizes[frame]))
        return tuple(int(n) for n in counts)

    stops = tuple(
        dataclasses.replace(
            stop,
            clouds={frame: cloud[kept(stop, frame)] for frame, cloud in stop.clouds.items()},
            scan_sizes={frame: sizes(stop, frame) for frame in stop.scan_sizes},
        )
        for stop in problem.stops
    )
    return dataclasses.replace(problem, stops=stops)


def run_trial(case: str, seed: int, rate: float, methods: Sequence[str]) -> dict[str, Trial]:
    from pipeline.baselines import entire_cloud, without_rough_refinement
    from pipeline.calibrate import calibrate
    from pipeline.config import config_from_mapping, resolved
    from pipeline.stages.setup import order_lidars
    from pipeline.synth import simulate_problem
    from pipeline.transforms import invert

    problem, truth = simulate_problem(case, seed, rate)
    config = PipelineConfig()
    frames = [lidar.frame for lidar in order_lidars(problem, config.frames)]
    T_true = true_T_ref_lidar(truth, frames)
    initial = {lidar.frame: lidar.T_base_lidar for lidar in problem.lidars}
    T_initial = np.stack([invert(initial[frames[0]]) @ initial[f] for f in frames])
    trials: dict[str, Trial] = {}
    t, r = _errors(T_initial, T_true)
    trials["initial"] = Trial(t, r)
    for method in methods:
        started = time.perf_counter()
        if method == "entire_cloud":
            baseline = entire_cloud(problem, config)
            estimate = np.stack(
                [invert(baseline.T_base_lidar[0]) @ T for T in baseline.T_base_lidar]
            )
            optimisation = baseline.optimisation
            passed = None
            stages: dict[str, float] = {}
            sigma_t: list[float] = []
            sigma_r: list[float] = []
            t, r = _errors(estimate, T_true)
        else:
            if method in CONFIG_METHODS:
                result = calibrate(problem, method_config(method))
            elif method == "labelled_stage1":
                data = resolved(config)
                data["denoise"]["enabled"] = False
                result = calibrate(without_bleeding(problem, truth), config_from_mapping(data))
            elif method == "without_rr":
                result = without_rough_refinement(problem, config)
            else:
                raise SystemExit(f"unknown method {method!r}; choose from {METHODS}")
            optimisation = result.optimisation
            passed = result.passed
            stages = {name: report.seconds for name, report in result.stages.items()}
            t, r, sigma_t, sigma_r = calibration_errors(result, truth)
        seconds = time.perf_counter() - started
        history_t, history_r = _history(optimisation.T_ref_lidar_per_iteration, T_true)
        trials[method] = Trial(
            t,
            r,
            seconds,
            optimisation.iterations,
            optimisation.converged,
            passed,
            history_t,
            history_r,
            stages,
            sigma_t,
            sigma_r,
        )
    return trials


# -- tables ----------------------------------------------------------------------------------


def accuracy_table(results: dict[str, list[dict[str, Trial]]], methods: Sequence[str]) -> str:
    lines = [
        "| case | method | trials | mean t (mm) | max t (mm) | mean r (deg) | max r (deg) "
        "| iterations | converged | verdict passed | seconds |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for case, trials in results.items():
        for method in ("initial", *methods):
            runs = [trial[method] for trial in trials if method in trial]
            t = np.concatenate([run.translation for run in runs]) * 1000
            r = np.concatenate([run.rotation for run in runs])
            if method == "initial":
                extra = "| | | | "
            else:
                passed = [run.passed for run in runs if run.passed is not None]
                extra = (
                    f"| {np.mean([run.iterations for run in runs]):.0f} "
                    f"| {sum(run.converged for run in runs)}/{len(runs)} "
                    f"| {f'{sum(passed)}/{len(passed)}' if passed else 'n/a'} "
                    f"| {np.mean([run.seconds for run in runs]):.1f} "
                )
            lines.append(
                f"| {case} | {method} | {len(runs)} | {t.mean():.2f} | {t.max():.2f} "
                f"| {r.mean():.3f} | {r.max():.3f} {extra}|"
            )
    return "\n".join(lines)


PAIRS = (
    ("with_stage1", "without_stage1"),
    ("labelled_stage1", "without_stage1"),
    ("proposed", "point_to_point"),
)
"""Methods compared trial by trial when both ran: (candidate, baseline)."""


def paired_table(results: dict[str, list[dict[str, Trial]]], method: str, baseline: str) -> str:
    """Per case and pooled: the mean of (method - baseline) over the same trials and LiDARs, its
    standard error, and how many came out worse by more than 0.5 mm / 0.01 deg."""
    lines = [
        f"| case | pairs | {method} - {baseline}: t mm (sem) | r deg (sem) "
        "| worse by > 0.5 mm | worse by > 0.01 deg |",
        "|---|---|---|---|---|---|",
    ]
    pooled: list[tuple[NDArray[np.float64], NDArray[np.float64]]] = []
    for case, trials in [*results.items(), ("all", [])]:
        if case == "all":
            if len(pooled) < 2:
                break
            dt = np.concatenate([t for t, _ in pooled])
            dr = np.concatenate([r for _, r in pooled])
        else:
            both = [trial for trial in trials if method in trial and baseline in trial]
            if not both:
                continue
            dt = 1000 * np.concatenate(
                [np.subtract(t[method].translation, t[baseline].translation) for t in both]
            )
            dr = np.concatenate(
                [np.subtract(t[method].rotation, t[baseline].rotation) for t in both]
            )
            pooled.append((dt, dr))

        def sem(values: NDArray[np.float64]) -> float:
            return float(values.std(ddof=1) / np.sqrt(len(values))) if len(values) > 1 else 0.0

        lines.append(
            f"| {case} | {len(dt)} | {dt.mean():+.2f} ({sem(dt):.2f}) "
            f"| {dr.mean():+.4f} ({sem(dr):.4f}) | {int((dt > 0.5).sum())} "
            f"| {int((dr > 0.01).sum())} |"
        )
    return "\n".join(lines)


def stddev_table(results: dict[str, list[dict[str, Trial]]], methods: Sequence[str]) -> str:
    """The reported 1-sigma against the true error: for a calibrated Gaussian, |error| / |sigma|
    (norms over the three axes) has an RMS of 1; above 1, the reported stddev is optimistic."""
    lines = [
        "| case | method | median reported sigma: mm / deg | RMS error/sigma: translation "
        "| rotation | max error/sigma: translation | rotation |",
        "|---|---|---|---|---|---|---|",
    ]
    for case, trials in results.items():
        for method in methods:
            runs = [t[method] for t in trials if method in t and t[method].stddev_translation]
            if not runs:
                continue
            sigma_t = np.concatenate([run.stddev_translation for run in runs])
            sigma_r = np.concatenate([run.stddev_rotation for run in runs])
            ratio_t = np.concatenate([run.translation for run in runs]) / np.maximum(sigma_t, 1e-12)
            ratio_r = np.concatenate([run.rotation for run in runs]) / np.maximum(sigma_r, 1e-12)
            lines.append(
                f"| {case} | {method} | {1000 * np.median(sigma_t):.2f} / {np.median(sigma_r):.4f} "
                f"| {np.sqrt(np.mean(ratio_t**2)):.1f} | {np.sqrt(np.mean(ratio_r**2)):.1f} "
                f"| {ratio_t.max():.1f} | {ratio_r.max():.1f} |"
            )
    return "\n".join(lines)


def stage_table(results: dict[str, list[dict[str, Trial]]]) -> str:
    stages: list[str] = []
    for trials in results.values():
        for trial in trials:
            if "proposed" in trial:
                stages = list(trial["proposed"].stages)
                break
    if not stages:
        return ""
    lines = [
        "| case | " + " | ".join(stages) + " |",
        "|---|" + "---|" * len(stages),
    ]
    for case, trials in results.items():
        runs = [trial["proposed"] for trial in trials if "proposed" in trial]
        means = [np.mean([run.stages.get(s, 0.0) for run in runs]) for s in stages]
        lines.append(f"| {case} | " + " | ".join(f"{m:.2f}" for m in means) + " |")
    return "\n".join(lines)


def convergence(
    results: dict[str, list[dict[str, Trial]]], methods: Sequence[str]
) -> dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """Mean error per iteration over the set-1 trials (a run that stopped early holds its last
    value)."""
    curves: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
    for method in methods:
        runs = [
            trial[method]
            for case, trials in results.items()
            if case.startswith("set1")
            for trial in trials
            if method in trial
        ]
        if not runs:
            continue
        length = max(len(run.history_translation) for run in runs)

        def padded(values: list[float], length: int = length) -> list[float]:
            return values + [values[-1]] * (length - len(values))

        curves[method] = (
            np.mean([padded(run.history_translation) for run in runs], axis=0),
            np.mean([padded(run.history_rotation) for run in runs], axis=0),
        )
    return curves


def convergence_table(curves: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]]) -> str:
    marks = [0, 5, 10, 20, 30, 50, 100, 200]
    lines = [
        "| method | " + " | ".join(f"it {k}" for k in marks) + " |",
        "|---|" + "---|" * len(marks),
    ]
    for method, (t, r) in curves.items():
        cells = [
            f"{t[min(k, len(t) - 1)] * 1000:.1f} mm / {r[min(k, len(r) - 1)]:.2f}°" for k in marks
        ]
        lines.append(f"| {method} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(curves: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    for method, (t, r) in curves.items():
        left.plot(np.arange(len(t)), t * 1000, label=method)
        right.plot(np.arange(len(r)), r, label=method)
    left.set(xlabel="iteration", ylabel="translation error (mm)", yscale="log")
    right.set(xlabel="iteration", ylabel="rotation error (deg)", yscale="log")
    left.legend()
    figure.suptitle("Set 1: mean extrinsic error per stage-4 iteration")
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


# -- file -> result.json timing ----------------------------------------------------------------

_CHILD = """
import json, resource, sys, time
started, cpu = time.perf_counter(), time.process_time()
from pipeline.calibrate import calibrate
from pipeline.config import PipelineConfig
from pipeline.io import read_recording
from pipeline.result import dumps
config = PipelineConfig()
read_started = time.perf_counter()
problem = read_recording(sys.argv[1], config.reader)
read = time.perf_counter() - read_started
result = calibrate(problem, config)
open(sys.argv[2], "w").write(dumps(result, read_seconds=read))
print(json.dumps({
    "wall_s": time.perf_counter() - started,
    "cpu_s": time.process_time() - cpu,
    "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    "points": problem.kept_points(),
}))
"""


def timing(case: str, recordings: Path) -> dict[str, object]:
    from pipeline.synth.recording import write_recording

    directory = recordings / f"{case}-full"
    if not (directory / "recording").exists():
        print(f"writing a full-rate {case} recording to {directory} ...", file=sys.stderr)
        write_recording(case, directory, seed=0)
    bag = directory / "recording"
    size_mb = sum(f.stat().st_size for f in bag.rglob("*") if f.is_file()) / 1e6
    output = directory / "result.json"
    started = time.perf_counter()
    child = subprocess.run(
        [sys.executable, "-c", _CHILD, str(bag), str(output)],
        check=True,
        capture_output=True,
        text=True,
        env={**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"},
    )
    process_wall = time.perf_counter() - started
    measured = json.loads(child.stdout.strip().splitlines()[-1])
    document = json.loads(output.read_text())
    return {
        "case": case,
        "size_mb": size_mb,
        "process_wall_s": process_wall,
        **measured,
        "stages": {name: stage["seconds"] for name, stage in document["stages"].items()},
        "passed": document["verdict"]["passed"],
        "load": os.getloadavg()[0],
    }


def timing_table(rows: list[dict[str, object]]) -> str:
    lines = [
        "| recording | size (MB) | points | process wall (s) | in-process wall (s) | CPU (s) "
        "| peak RSS (MB) | load avg | verdict |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row['case']} full rate | {row['size_mb']:.0f} | {row['points']} "
            f"| {row['process_wall_s']:.1f} | {row['wall_s']:.1f} | {row['cpu_s']:.1f} "
            f"| {row['peak_rss_mb']:.0f} | {row['load']:.1f} "
            f"| {'passed' if row['passed'] else 'FAILED'} |"
        )
    stages = list(rows[0]["stages"]) if rows else []  # type: ignore[call-overload]
    if stages:
        lines += ["", "| recording | " + " | ".join(stages) + " |", "|---|" + "---|" * len(stages)]
        for row in rows:
            values = row["stages"]
            assert isinstance(values, dict)
            lines.append(
                f"| {row['case']} | " + " | ".join(f"{values[s]:.2f}" for s in stages) + " |"
            )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="2 seeds, rate 0.1, two cases")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument(
        "--rate", type=float, default=1.0, help="LiDAR point rate scale of the trials (1: full)"
    )
    parser.add_argument("--cases", nargs="*", default=list(CASES))
    parser.add_argument("--methods", nargs="*", default=list(METHODS))
    parser.add_argument("--no-timing", action="store_true")
    parser.add_argument("--timing-cases", nargs="*", default=["set1-box", "set2-box"])
    parser.add_argument("--plot", type=Path, default=Path("bench-out/convergence.png"))
    parser.add_argument("--recordings", type=Path, default=Path("/tmp/fleetcal-bench"))
    args = parser.parse_args(argv)
    if args.quick:
        args.seeds, args.rate = min(args.seeds, 2), min(args.rate, 0.1)
        args.cases = [c for c in args.cases if c in ("set1-box", "set2-box")] or ["set1-box"]
        args.timing_cases = args.timing_cases[:1]
    results: dict[str, list[dict[str, Trial]]] = defaultdict(list)
    for case in args.cases:
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            started = time.perf_counter()
            trial = run_trial(case, seed, args.rate, args.methods)
            results[case].append(trial)
            summary = ", ".join(
                f"{m} {1000 * max(trial[m].translation):.1f} mm / {max(trial[m].rotation):.3f}°"
                for m in ("initial", *args.methods)
            )
            print(
                f"{case} seed {seed}: {summary} ({time.perf_counter() - started:.0f} s)",
                file=sys.stderr,
                flush=True,
            )
    print(f"## Accuracy ({args.seeds} seeds per case, rate scale {args.rate})\n")
    print(accuracy_table(results, args.methods))
    for method, baseline in PAIRS:
        if method in args.methods and baseline in args.methods:
            print(f"\n## {method} against {baseline}, trial by trial\n")
            print(paired_table(results, method, baseline))
    print("\n## Reported 1-sigma against the true error\n")
    print(stddev_table(results, args.methods))
    print("\n## Stage times of the proposed method (mean seconds per trial)\n")
    print(stage_table(results))
    curves = convergence(results, args.methods)
    if curves:
        print("\n## Convergence on set 1 (mean error at stage-4 iteration k)\n")
        print(convergence_table(curves))
        args.plot.parent.mkdir(parents=True, exist_ok=True)
        plot(curves, args.plot)
        print(f"\nplot: {args.plot}")
    if not args.no_timing:
        args.recordings.mkdir(parents=True, exist_ok=True)
        rows = [timing(case, args.recordings) for case in args.timing_cases]
        print("\n## File -> result.json, full rate (fresh process each)\n")
        print(timing_table(rows))


if __name__ == "__main__":
    main()
