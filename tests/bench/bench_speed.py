"""How close `fleetcal calibrate` runs to the floor: reading the recording (issue 17).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m tests.bench.bench_speed [--scenario set1-box ...]

For each full-rate scenario (synthesised once, cached under `--cache`), each in a fresh process:
(a) the floor: read and deserialise every message with rosbags and nothing else; (b) `fleetcal
calibrate` as a user runs it, with the seconds of each stage from its result.json; (r) the report
images (`pipeline.report.render_report`) of that calibration, timed alone, with matplotlib already
imported as in the service's pool children (`load_renderer`, preloaded by their fork server; its
own seconds are in the row's detail). CPU seconds (user +
system, what a loaded machine cannot blur), wall seconds and peak RSS come from the child's
rusage; the ratios are of CPU seconds, all measured in this one run. The load average is printed.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

DEFAULT_SCENARIOS = ("set1-box", "set2-box")
DEFAULT_CACHE = Path(tempfile.gettempdir()) / "fleetcal-bench-speed"

# (a): every message read and deserialised, as `pipeline.io` must at the least.
_RAW_READ = """
import sys
from pathlib import Path
from rosbags.highlevel import AnyReader
messages = 0
with AnyReader([Path(sys.argv[1])]) as reader:
    for connection, _, raw in reader.messages():
        reader.deserialize(raw, connection.msgtype)
        messages += 1
print(messages)
"""

# (r): the report images of a calibration, timed alone (the read and calibration before it not).
_REPORT = """
import json, sys, time
from pathlib import Path
from pipeline.calibrate import calibrate
from pipeline.config import PipelineConfig
from pipeline.io import read_recording
from pipeline.report import load_renderer, render_report
config = PipelineConfig()
problem = read_recording(Path(sys.argv[1]), config.reader)
result = calibrate(problem, config)
cpu = time.process_time()
load_renderer()
load_cpu = time.process_time() - cpu
wall, cpu = time.perf_counter(), time.process_time()
images = render_report(problem, result)
print(json.dumps({
    "wall_s": time.perf_counter() - wall,
    "cpu_s": time.process_time() - cpu,
    "load_cpu_s": load_cpu,
    "bytes": sum(len(png) for png in images.values()),
}))
"""


@dataclass(frozen=True)
class Measured:
    """One child process: CPU (user + system) and wall seconds, peak RSS (MiB), its stdout."""

    cpu_s: float
    wall_s: float
    peak_mib: float
    stdout: str


def measured(args: list[str], ok: tuple[int, ...] = (0,)) -> Measured:
    """Run `args` in a fresh process; its CPU seconds, wall seconds and peak RSS (rusage)."""
    started = time.perf_counter()
    child = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert child.stdout is not None and child.stderr is not None
    # Read the pipes while it runs, then reap it ourselves: wait4 returns its own rusage.
    stdout, stderr = child.stdout.read(), child.stderr.read()
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - started
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode not in ok:
        raise RuntimeError(f"{' '.join(args[:4])} exited {child.returncode}:\n{stderr[-2000:]}")
    return Measured(usage.ru_utime + usage.ru_stime, wall, usage.ru_maxrss / 1024, stdout)


def recording(scenario: str, cache: Path, seed: int) -> Path:
    """The full-rate recording of `scenario`, synthesised into `cache` on first use."""
    from pipeline.synth.recording import RECORDING_DIR, write_recording

    done = cache / f"{scenario}-seed{seed}"
    if not done.is_dir():
        partial = cache / f"{scenario}-seed{seed}.partial"
        if partial.exists():
            raise SystemExit(f"{partial} is left from an interrupted run: delete it and rerun")
        started = time.perf_counter()
        write_recording(scenario, partial, seed=seed)
        partial.rename(done)
        print(f"synthesised {scenario} in {time.perf_counter() - started:.0f} s", file=sys.stderr)
    return done / RECORDING_DIR


def _size_mb(path: Path) -> float:
    files = [path] if path.is_file() else [f for f in path.rglob("*") if f.is_file()]
    return sum(f.stat().st_size for f in files) / 1e6


def bench(path: Path) -> list[tuple[str, Measured, str]]:
    """Rows (what, measurement, detail) for one recording."""
    python = sys.executable
    raw = measured([python, "-c", _RAW_READ, str(path)])
    with tempfile.TemporaryDirectory(prefix="bench-speed-") as scratch:
        out = Path(scratch) / "result.json"
        # Exit 1 is a failed verdict, still a whole run.
        cli = measured(
            [
                python,
                "-c",
                "from workers.cli import main; main()",
                "calibrate",
                str(path),
                "-o",
                str(out),
            ],
            ok=(0, 1),
        )
        stages = json.loads(out.read_text())["stages"]
    report = measured([python, "-c", _REPORT, str(path)])
    drawn = json.loads(report.stdout.strip().splitlines()[-1])
    per_stage = ", ".join(f"{name} {stage['seconds']:.2f}" for name, stage in stages.items())
    return [
        ("(a) raw read (rosbags)", raw, f"{raw.stdout.strip()} messages"),
        ("(b) fleetcal calibrate", cli, f"stages (wall s): {per_stage}"),
        (
            "(r) report images",
            Measured(drawn["cpu_s"], drawn["wall_s"], report.peak_mib, ""),
            f"{drawn['bytes'] / 1e3:.0f} kB of PNG; importing matplotlib first took "
            f"{drawn['load_cpu_s']:.2f} s CPU, once per process; peak is the whole process's",
        ),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", nargs="+", default=list(DEFAULT_SCENARIOS))
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)

    paths = {scenario: recording(scenario, args.cache, args.seed) for scenario in args.scenario}
    load = " / ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"{os.cpu_count()} cores, load average {load} (1 / 5 / 15 min) before the runs\n")
    print("| scenario | MB | what | CPU s | wall s | peak RSS MiB | CPU / (a) | detail |")
    print("|---|---:|---|---:|---:|---:|---:|---|")
    for scenario, path in paths.items():
        rows = bench(path)
        floor = rows[0][1].cpu_s
        for what, m, detail in rows:
            print(
                f"| {scenario} | {_size_mb(path):.0f} | {what} | {m.cpu_s:.2f} | {m.wall_s:.2f} "
                f"| {m.peak_mib:.0f} | {m.cpu_s / floor:.1f}x | {detail} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
