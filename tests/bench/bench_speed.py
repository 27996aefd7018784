"""How close `fleetcal calibrate` runs to the floor: reading the recording (issue 17).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m tests.bench.bench_speed [--scenario set1-box ...]
        [--random-seeds 1000 1001 1002 1003] [--scaling]

For each full-rate scenario (synthesised once, cached under `--cache`), and each random scenario
of `--random-seeds` (`fleetcal synth random`; by default the first seed of each routine class:
1000 rotate, 1001 lane, 1002 figure-eight, 1003 loop), each in a fresh process:
(a) the floor: read and deserialise every message with rosbags and nothing else; (b) `fleetcal
calibrate` as a user runs it, with the seconds of each stage from its result.json; (c) the
service's worker job on the same file (`workers.job.calibrate_run`: the upload fetched from
local storage, read, calibrated, result document and report images stored), with matplotlib
imported first as in the service's pool children, and its CPU counted from the job's start (a
pool child has imported the pipeline before it takes a job); the queue's hand-off and the
database commit around it are not in it; (r) the report images
(`pipeline.report.render_report`) of that calibration, timed alone, likewise (its import's
seconds are in the row's detail). CPU seconds (user + system, what a loaded machine cannot blur)
and wall seconds come from the child's rusage, its peak RSS from its own VmHWM at exit; the
ratios are of CPU seconds, all measured in this one run. The load average is printed.

`--scaling` prints instead how `fleetcal calibrate` grows with the work: set 1 with boxes at
0.25, 0.5, 1, 2 and 4 times the point rate (about 25-400 MB; two LiDARs, 16 stops) and random
scenarios of 2-5 LiDARs and 6-28 stops (`--scaling-seeds`), each row with its points and CPU
seconds per million points read.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import TYPE_CHECKING, Any  # noqa: E402

if TYPE_CHECKING:
    from pipeline.synth.scenarios import ScenarioSpec

DEFAULT_SCENARIOS = ("set1-box", "set2-box")
DEFAULT_RANDOM_SEEDS = (1000, 1001, 1002, 1003)
"""The first seed of each routine class: rotate, lane, figure-eight, loop."""
SCALING_RATES = (0.25, 0.5, 1.0, 2.0, 4.0)
DEFAULT_SCALING_SEEDS = (1001, 1003, 1005, 1000, 1011)
"""Random scenarios of 2, 2, 3, 4 and 5 LiDARs and 6 to 28 stops (the table gives each)."""
DEFAULT_CACHE = Path(tempfile.gettempdir()) / "fleetcal-bench-speed"

# (a): every message read and deserialised, as `pipeline.io` must at the least.
_RAW_READ = """
import sys
from pathlib import Path
from rosbags.highlevel import AnyReader
messages = points = 0
with AnyReader([Path(sys.argv[1])]) as reader:
    for connection, _, raw in reader.messages():
        message = reader.deserialize(raw, connection.msgtype)
        messages += 1
        if connection.msgtype == "sensor_msgs/msg/PointCloud2":
            points += message.width * message.height
print(messages, points)
"""

# (c): the service's worker job on the recording's file, uploaded to local storage first.
_SERVICE_RUN = """
import json, sys, time, uuid
from pathlib import Path
from pipeline.io.formats import detect_format_from_head
from pipeline.report import load_renderer
from service.settings import Settings
from service.storage import make_storage
from workers import job
from workers.context import JobSpec
source, scratch = Path(sys.argv[1]), Path(sys.argv[2])
settings = Settings(data_dir=scratch, storage_url=(scratch / "storage").as_uri())
key = f"recordings/bench/{uuid.uuid4()}"
pending = make_storage(settings).begin_upload(key)
with source.open("rb") as file:
    head = file.read(4096)
    pending.write(head)
    while chunk := file.read(1 << 20):
        pending.write(chunk)
pending.commit()
detected = detect_format_from_head(head)
spec = JobSpec(
    run_id=str(uuid.uuid4()), attempt=1, robot_id="bench", kind="end_of_line",
    storage_key=key, upload_format=detected.value, config=None, settings=settings,
)
load_renderer()
wall, cpu = time.perf_counter(), time.process_time()
document = job.calibrate_run(spec, lambda name, progress: None)
print(json.dumps({
    "wall_s": time.perf_counter() - wall,
    "cpu_s": time.process_time() - cpu,
    "report_s": document["stages"]["report"]["seconds"],
    "images": len(document["report"].get("images", [])),
}))
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


# Prepended to every child's `-c` script: at exit it prints its peak RSS (VmHWM, of its own
# memory since exec). The rusage `ru_maxrss` is no use for this: Linux carries the parent's
# high-water mark over the child's exec, so a parent that synthesised a recording in-process made
# every child look as large as itself.
_PEAK_AT_EXIT = """
import atexit as _atexit, sys as _sys
def _peak():
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmHWM:"):
                print("bench-speed-peak-kib", line.split()[1], file=_sys.stderr, flush=True)
_atexit.register(_peak)
"""
_PEAK_MARK = "bench-speed-peak-kib"


def _peak_mib(stderr: str) -> float | None:
    """The child's own peak RSS (MiB) that `_PEAK_AT_EXIT` printed, if it did."""
    for line in reversed(stderr.splitlines()):
        if line.startswith(_PEAK_MARK):
            return int(line.split()[1]) / 1024
    return None


def measured(args: list[str], ok: tuple[int, ...] = (0,)) -> Measured:
    """Run `args` (`python -c SCRIPT ...`) in a fresh process; its CPU and wall seconds (rusage)
    and its own peak RSS (`_PEAK_AT_EXIT`)."""
    if args[1] == "-c":
        args = [args[0], "-c", _PEAK_AT_EXIT + args[2], *args[3:]]
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
    peak = _peak_mib(stderr)
    if peak is None:
        raise RuntimeError(f"{args[0]} did not report its peak memory:\n{stderr[-2000:]}")
    return Measured(usage.ru_utime + usage.ru_stime, wall, peak, stdout)


def recording(scenario: str, cache: Path, seed: int, rate_scale: float = 1.0) -> Path:
    """The recording of `scenario` (a named one, or `random-N`: `fleetcal synth random --seed
    N`) at `rate_scale` of the point rate, synthesised into `cache` on first use."""
    from pipeline.synth.recording import RECORDING_DIR, write_recording

    name = f"{scenario}-seed{seed}" + ("" if rate_scale == 1.0 else f"-rate{rate_scale:g}")
    done = cache / name
    if not done.is_dir():
        partial = cache / f"{name}.partial"
        if partial.exists():
            shutil.rmtree(partial)  # left by an interrupted run: synthesise it again
        started = time.perf_counter()
        write_recording(scenario_spec(scenario), partial, seed=seed, rate_scale=rate_scale)
        partial.rename(done)
        print(f"synthesised {name} in {time.perf_counter() - started:.0f} s", file=sys.stderr)
    return done / RECORDING_DIR


def _random_seed(scenario: str) -> int | None:
    """N for `random-N` (`fleetcal synth random --seed N`), None for a named scenario."""
    prefix = "random-"
    return int(scenario.removeprefix(prefix)) if scenario.startswith(prefix) else None


def scenario_spec(scenario: str) -> ScenarioSpec:
    """The spec of a named scenario or of `random-N`."""
    from pipeline.synth.random_scenario import random_scenario
    from pipeline.synth.scenarios import get_scenario

    seed = _random_seed(scenario)
    return get_scenario(scenario) if seed is None else random_scenario(seed)


def describe_scenario(scenario: str) -> str:
    """`random-1000 (rotate/spinning/large)` for a random scenario, else the name."""
    if _random_seed(scenario) is None:
        return scenario
    return f"{scenario} ({scenario_spec(scenario).scenario_class})"


def _stops(motion: Any) -> int:
    """Stops of a scenario's motion: an arc's `stops`, a route's dwell times."""
    return int(motion.stops) if hasattr(motion, "stops") else len(motion.dwell_s)


def _upload_file(path: Path) -> Path:
    """The file a robot would upload for the recording at `path` (a bag directory's MCAP)."""
    if path.is_file():
        return path
    files = sorted(path.glob("*.mcap"))
    if len(files) != 1:
        raise SystemExit(f"{path}: expected one .mcap file to upload, found {len(files)}")
    return files[0]


def _size_mb(path: Path) -> float:
    files = [path] if path.is_file() else [f for f in path.rglob("*") if f.is_file()]
    return sum(f.stat().st_size for f in files) / 1e6


def raw_read(path: Path) -> tuple[Measured, int, int]:
    """(a), and the recording's messages and LiDAR points."""
    raw = measured([sys.executable, "-c", _RAW_READ, str(path)])
    messages, points = (int(x) for x in raw.stdout.split())
    return raw, messages, points


def calibrate_cli(path: Path) -> tuple[Measured, dict[str, Any]]:
    """(b), and its result.json's stages."""
    with tempfile.TemporaryDirectory(prefix="bench-speed-") as scratch:
        out = Path(scratch) / "result.json"
        # Exit 1 is a failed verdict, still a whole run.
        cli = measured(
            [
                sys.executable,
                "-c",
                "from workers.cli import main; main()",
                "calibrate",
                str(path),
                "-o",
                str(out),
            ],
            ok=(0, 1),
        )
        stages: dict[str, Any] = json.loads(out.read_text())["stages"]
    return cli, stages


def bench(path: Path) -> list[tuple[str, Measured, str]]:
    """Rows (what, measurement, detail) for one recording."""
    python = sys.executable
    raw, messages, points = raw_read(path)
    cli, stages = calibrate_cli(path)
    with tempfile.TemporaryDirectory(prefix="bench-speed-service-") as scratch:
        service = measured([python, "-c", _SERVICE_RUN, str(_upload_file(path)), scratch])
    job = json.loads(service.stdout.strip().splitlines()[-1])
    report = measured([python, "-c", _REPORT, str(path)])
    drawn = json.loads(report.stdout.strip().splitlines()[-1])
    per_stage = ", ".join(f"{name} {stage['seconds']:.2f}" for name, stage in stages.items())
    return [
        ("(a) raw read (rosbags)", raw, f"{messages} messages, {points / 1e6:.1f} M points"),
        ("(b) fleetcal calibrate", cli, f"stages (wall s): {per_stage}"),
        (
            "(c) the service's worker job",
            Measured(job["cpu_s"], job["wall_s"], service.peak_mib, ""),
            f"download, read, calibrate, {job['images']} report images stored "
            f"({job['report_s']:.2f} s); matplotlib imported before, as in the pool",
        ),
        (
            "(r) report images",
            Measured(drawn["cpu_s"], drawn["wall_s"], report.peak_mib, ""),
            f"{drawn['bytes'] / 1e3:.0f} kB of PNG; importing matplotlib first took "
            f"{drawn['load_cpu_s']:.2f} s CPU, once per process; peak is the whole process's",
        ),
    ]


def scaling_table(cache: Path, seed: int, random_seeds: list[int]) -> None:
    """`--scaling`: (a) and (b) per recording, with its size, LiDARs, stops and points."""
    cases = [("set1-box", seed, rate) for rate in SCALING_RATES]
    cases += [(f"random-{n}", n, 1.0) for n in random_seeds]
    print(
        "| recording | rate | MB | LiDARs | stops | M points | (a) CPU s | (b) CPU s | (b) / (a) "
        "| (b) CPU s per M points | (b) peak RSS MiB |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for scenario, synth_seed, rate in cases:
        path = recording(scenario, cache, synth_seed, rate)
        spec = scenario_spec(scenario)
        raw, _, points = raw_read(path)
        cli, _ = calibrate_cli(path)
        print(
            f"| {describe_scenario(scenario)} | {rate:g} | {_size_mb(path):.0f} "
            f"| {len(spec.lidars)} | {_stops(spec.motion)} | {points / 1e6:.1f} | {raw.cpu_s:.2f} "
            f"| {cli.cpu_s:.2f} | {cli.cpu_s / raw.cpu_s:.1f}x | {cli.cpu_s / (points / 1e6):.3f} "
            f"| {cli.peak_mib:.0f} |",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", nargs="*", default=list(DEFAULT_SCENARIOS))
    parser.add_argument(
        "--random-seeds",
        nargs="*",
        type=int,
        default=list(DEFAULT_RANDOM_SEEDS),
        help="random scenarios (`fleetcal synth random --seed N`) to time as well",
    )
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--scaling", action="store_true", help="the table of cost against size")
    parser.add_argument("--scaling-seeds", nargs="*", type=int, default=list(DEFAULT_SCALING_SEEDS))
    args = parser.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    load = " / ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"{os.cpu_count()} cores, load average {load} (1 / 5 / 15 min) before the runs\n")
    if args.scaling:
        scaling_table(args.cache, args.seed, args.scaling_seeds)
        return

    scenarios = [*args.scenario, *(f"random-{n}" for n in args.random_seeds)]
    paths = {
        # A random scenario is synthesised with its own seed, as `fleetcal synth random` does.
        scenario: recording(scenario, args.cache, _random_seed(scenario) or args.seed)
        for scenario in scenarios
    }
    print("| scenario | MB | what | CPU s | wall s | peak RSS MiB | CPU / (a) | detail |")
    print("|---|---:|---|---:|---:|---:|---:|---|")
    for scenario, path in paths.items():
        rows = bench(path)
        floor = rows[0][1].cpu_s
        for what, m, detail in rows:
            print(
                f"| {describe_scenario(scenario)} | {_size_mb(path):.0f} | {what} | {m.cpu_s:.2f} "
                f"| {m.wall_s:.2f} | {m.peak_mib:.0f} | {m.cpu_s / floor:.1f}x | {detail} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
