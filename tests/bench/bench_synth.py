"""Time of `pipeline.synth`: in-memory problems and written recordings, one row per case.

    .venv/bin/python -m tests.bench.bench_synth [--full] [--cases tiny,set1-box@0.1]

Each case is `scenario@rate_scale`. Wall clock and the process's CPU time are both given (the CPU
figure is what a shared, loaded machine cannot blur; the load average is printed with the table).
`--full` adds the full-rate set 1 recording (two Mid-70 at 100k points/s, 16 stops, ~100 MB).
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path

from pipeline.synth import simulate_problem
from pipeline.synth.recording import write_recording

DEFAULT_CASES = ("tiny@1", "set1-box@0.1", "set2-capsule@0.1", "spinning@0.1", "driven@0.1")


def _size_mb(path: Path) -> float:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file()) / 1e6


def _timed(action: object) -> tuple[float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    action()  # type: ignore[operator]
    return time.perf_counter() - wall, time.process_time() - cpu


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--cases", default=",".join(DEFAULT_CASES))
    parser.add_argument("--full", action="store_true", help="add set1-box at full rate")
    args = parser.parse_args()
    cases = [c for c in args.cases.split(",") if c] + (["set1-box@1"] if args.full else [])
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        for case in cases:
            name, _, rate = case.partition("@")
            rate_scale = float(rate or 1.0)
            problem_box: list[int] = []
            memory = _timed(
                lambda: problem_box.append(simulate_problem(name, 0, rate_scale)[0].kept_points())  # noqa: B023
            )
            out = Path(scratch) / case
            written = _timed(lambda: write_recording(name, out, seed=0, rate_scale=rate_scale))  # noqa: B023
            rows.append((case, problem_box[0], *memory, *written, _size_mb(out / "recording")))
            shutil.rmtree(out)
    print(f"load average: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    header = ("case", "stop pts", "problem s", "(cpu)", "write s", "(cpu)", "bag MB")
    print("{:<20} {:>10} {:>10} {:>7} {:>8} {:>7} {:>8}".format(*header))
    for row in rows:
        print("{:<20} {:>10} {:>10.2f} {:>7.2f} {:>8.2f} {:>7.2f} {:>8.1f}".format(*row))


if __name__ == "__main__":
    main()
