"""Where the cost's minimum lies (issue 13): stage 4 started from the pipeline's start and from
the true poses.

    .venv/bin/python -m tests.bench.bench_minimum --seeds 1060 [--rate-scale 1.0]
        [--variants default 'raw:segmentation.smooth_objects=false'] [--noise 1 1,0 0,1]
        [--cache /tmp/fleetcal-bench-minimum]

A calibration that ends off the truth either never got there (the start or the basin: a better
initialisation fixes it) or got there and walked away (the minimum of its cost is off the truth:
only the objective can fix it). For each seed (`fleetcal synth random --seed N`, synthesised once
into `CACHE/recordings/rate-F/noise-X/seed-N`), each noise setting and each variant, the stages
before stage 4 run as the pipeline runs them; stage 4 then starts once where the pipeline starts
it (stage 3's estimate, and global alignment's candidate when there is one) and once from the
true stop poses and extrinsics, and the table gives the error each ends at (the largest over the
non-reference LiDARs) with its iterations, and the error vector of the truth start's worst LiDAR
in the reference LiDAR's frame.

`--variants`: each `NAME:section.key=value,section.key=value` (values as JSON: `false`, `0.04`,
`"beam_quadric"` or a bare word), `default` for the default config. `--noise`: each setting
scales every LiDAR's range noise in the synthesised recording, one factor per LiDAR in the
scenario's order (`1,0`: the first LiDAR's noise kept, the second noise-free; one factor: every
LiDAR), to tell whose noise moves the minimum.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import shutil  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from pipeline.config import PipelineConfig  # noqa: E402
from pipeline.stages.state import CalibrationState  # noqa: E402
from pipeline.synth.scenarios import ScenarioSpec  # noqa: E402
from pipeline.synth.truth import Truth  # noqa: E402

DEFAULT_CACHE = Path("/tmp/fleetcal-bench-minimum")
BEFORE_STAGE_4 = ("moving_points", "denoise", "segmentation", "rough_refinement")


@dataclass(frozen=True)
class Variant:
    """A named config: the default with `overrides` ({"section.key": value})."""

    name: str
    overrides: dict[str, Any]

    def config(self) -> PipelineConfig:
        from pipeline.config import config_from_mapping, resolved

        data = resolved(PipelineConfig())
        for dotted, value in self.overrides.items():
            section, _, key = dotted.partition(".")
            if section not in data or not key:
                raise SystemExit(
                    f"variant {self.name!r}: {dotted!r} is not a section.key of the pipeline "
                    f"config (sections: {', '.join(sorted(data))})"
                )
            data[section][key] = value
        return config_from_mapping(data)


def parse_variant(text: str) -> Variant:
    """`NAME:section.key=value,...` (or `default`) as a `Variant`."""
    name, _, rest = text.partition(":")
    overrides: dict[str, Any] = {}
    for item in filter(None, (part.strip() for part in rest.split(","))):
        dotted, sep, raw = item.partition("=")
        if not sep:
            raise SystemExit(f"variant {text!r}: write each override as section.key=value")
        try:
            overrides[dotted.strip()] = json.loads(raw)
        except json.JSONDecodeError:
            overrides[dotted.strip()] = raw.strip()
    return Variant(name.strip() or "default", overrides)


def parse_noise(text: str) -> tuple[float, ...]:
    """`1,0` as (1.0, 0.0): a range-noise factor per LiDAR (one factor: every LiDAR)."""
    try:
        factors = tuple(float(part) for part in text.split(","))
    except ValueError:
        raise SystemExit(f"--noise {text!r}: write factors such as 1 or 1,0") from None
    if any(f < 0 for f in factors):
        raise SystemExit(f"--noise {text!r}: a noise factor cannot be negative")
    return factors


def with_noise(spec: ScenarioSpec, factors: Sequence[float]) -> ScenarioSpec:
    """`spec` with each LiDAR's range noise scaled by its factor (one factor: every LiDAR)."""
    if len(factors) not in (1, len(spec.lidars)):
        raise SystemExit(
            f"--noise has {len(factors)} factors; the scenario has {len(spec.lidars)} LiDARs "
            "(give one factor, or one per LiDAR)"
        )
    per_lidar = list(factors) * len(spec.lidars) if len(factors) == 1 else list(factors)
    lidars = tuple(
        mount.model_copy(
            update={
                "model": mount.model.model_copy(
                    update={"range_noise_m": mount.model.range_noise_m * factor}
                )
            }
        )
        for mount, factor in zip(spec.lidars, per_lidar, strict=True)
    )
    return spec.model_copy(update={"lidars": lidars})


def recording(cache: Path, rate_scale: float, seed: int, noise: Sequence[float]) -> Path:
    """The seed's recording with its noise scaled, synthesised unless a complete one is cached."""
    from pipeline.synth.random_scenario import random_scenario
    from pipeline.synth.recording import write_recording
    from pipeline.synth.truth import TRUTH_FILE

    label = ",".join(f"{f:g}" for f in noise)
    out = cache / "recordings" / f"rate-{rate_scale:g}" / f"noise-{label}" / f"seed-{seed}"
    if (out / TRUTH_FILE).is_file():  # written last: its presence means the bag is complete
        return out
    if out.exists():
        shutil.rmtree(out)
    write_recording(with_noise(random_scenario(seed), noise), out, seed=seed, rate_scale=rate_scale)
    return out


def true_T_G_ref(
    state: CalibrationState, truth: Truth, stop_times: Sequence[float]
) -> NDArray[np.float64]:
    """(J, 4, 4) the reference LiDAR's true pose at each of the state's stops, in the frame of
    its true pose at the first (the optimiser's gauge); each stop matched to the true stop whose
    still interval holds its middle (`stop_times`, ROS seconds), or by order where the clocks
    differ and the stops are as many."""
    from pipeline.transforms import invert

    T_base_ref = truth.lidar(state.lidars[0].frame).T_base_lidar_true
    matched = [
        next((s for s in truth.stops if s.t_start <= middle <= s.t_end), None)
        for middle in stop_times
    ]
    if any(stop is None for stop in matched):
        if len(truth.stops) != len(stop_times):
            raise SystemExit(
                f"{len(stop_times)} stops found, {len(truth.stops)} true ones, and their times "
                "do not match: cannot start from the truth"
            )
        matched = list(truth.stops)
    poses = [stop.T_odom_base_true @ T_base_ref for stop in matched if stop is not None]
    T_G_world = invert(poses[0])
    return np.stack([T_G_world @ pose for pose in poses])


@dataclass(frozen=True)
class Ending:
    """Where stage 4 ended: the worst non-reference LiDAR's error (mm, deg), its error vector in
    the reference LiDAR's frame (mm), the iterations and whether it converged."""

    translation_mm: float
    rotation_deg: float
    vector_mm: tuple[float, float, float]
    iterations: int
    converged: bool

    def cell(self) -> str:
        mark = "" if self.converged else ", not converged"
        return f"{self.translation_mm:.2f} / {self.rotation_deg:.3f} ({self.iterations}{mark})"


def ending(state: CalibrationState, truth_T_ref_lidar: NDArray[np.float64]) -> Ending:
    from tests.bench.bench_calibration import _errors

    t, r = _errors(state.T_ref_lidar, truth_T_ref_lidar)
    worst = int(np.argmax(t)) + 1
    vector = 1e3 * (state.T_ref_lidar[worst][:3, 3] - truth_T_ref_lidar[worst][:3, 3])
    optimised = state.optimised
    assert optimised is not None
    return Ending(
        1e3 * max(t),
        max(r),
        (float(vector[0]), float(vector[1]), float(vector[2])),
        optimised.iterations,
        optimised.converged,
    )


def run_case(directory: Path, variant: Variant) -> tuple[Ending, Ending]:
    """Stage 4 on one recording under `variant`: from the pipeline's start, from the truth."""
    from pipeline.io import read_recording
    from pipeline.stages.runner import Listeners, run_stages
    from pipeline.stages.sequence import STAGE_SEQUENCE
    from pipeline.stages.setup import initial_state
    from pipeline.synth.truth import load_truth
    from tests.bench.bench_calibration import true_T_ref_lidar

    config = variant.config()
    truth = load_truth(directory)
    problem = read_recording(directory / "recording", config.reader)
    stages = {stage.name: stage for stage in STAGE_SEQUENCE}
    listeners = Listeners()
    state, _ = run_stages(
        initial_state(problem, config.frames),
        config,
        [stages[name] for name in BEFORE_STAGE_4],
        listeners,
    )
    T_ref_lidar = true_T_ref_lidar(truth, [lidar.frame for lidar in state.lidars])
    aligned, _ = run_stages(state, config, [stages["global_alignment"]], listeners)
    from_start = stages["optimisation"].run(aligned, config, listeners).state
    middles = [(stop.t_start + stop.t_end) / 2.0 for stop in problem.stops]
    at_truth = dataclasses.replace(
        state,
        T_G_ref=true_T_G_ref(state, truth, middles),
        T_ref_lidar=T_ref_lidar.copy(),
        second_start=None,
    )
    from_truth = stages["optimisation"].run(at_truth, config, listeners).state
    return ending(from_start, T_ref_lidar), ending(from_truth, T_ref_lidar)


HEADER = (
    "| seed | class | noise | variant | from the pipeline's start: mm / deg (iterations) "
    "| from the truth: mm / deg (iterations) | from the truth: error vector in the reference "
    "frame (mm) |\n|---|---|---|---|---|---|---|"
)


def row(
    seed: int, scenario_class: str, noise: str, variant: str, start: Ending, truth: Ending
) -> str:
    vector = ", ".join(f"{v:+.1f}" for v in truth.vector_mm)
    return (
        f"| {seed} | {scenario_class} | {noise} | {variant} | {start.cell()} | {truth.cell()} "
        f"| {vector} |"
    )


def main(argv: Sequence[str] | None = None) -> None:
    from tests.bench.bench_random import parse_seeds

    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--seeds", default="1060", help="e.g. 1060 or 1000-1003,1060")
    parser.add_argument("--rate-scale", type=float, default=1.0)
    parser.add_argument("--variants", nargs="+", default=["default"])
    parser.add_argument("--noise", nargs="+", default=["1"], help="e.g. 1 0 1,0 0,1")
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    args = parser.parse_args(argv)
    from pipeline.synth.random_scenario import random_scenario

    variants = [parse_variant(text) for text in args.variants]
    noises = [parse_noise(text) for text in args.noise]
    print(HEADER, flush=True)
    for seed in parse_seeds(args.seeds):
        scenario_class = random_scenario(seed).scenario_class
        for noise in noises:
            directory = recording(args.cache, args.rate_scale, seed, noise)
            label = ",".join(f"{f:g}" for f in noise)
            for variant in variants:
                start, truth = run_case(directory, variant)
                print(row(seed, scenario_class, label, variant.name, start, truth), flush=True)


if __name__ == "__main__":
    main()
