"""Read throughput and peak memory of `pipeline.io.read_recording`, one row per format.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m tests.bench.bench_io [--size-mb 100] [--repeat 3]

Writes one stop-and-go recording (two LiDARs, 10 k points per scan at 10 Hz, 16 stops, odometry at
50 Hz) in every accepted format, then reads each in a fresh process: throughput is the file size
over the best of `--repeat` warm-cache reads, by wall clock and by the process's CPU time (the CPU
figure is what a shared, loaded machine cannot blur; the load average is printed with the table);
peak memory is traced (Python and numpy allocations) in a separate read, and the RSS high-water mark
over the process's baseline is given beside it. "Kept" is the stop clouds the problem holds
(N x 3 float64).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tarfile  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
import zipfile  # noqa: E402
from pathlib import Path  # noqa: E402

POINTS_PER_SCAN = 10_000
BYTES_PER_POINT = 16  # float32 x, y, z, intensity


def _size(path: Path) -> int:
    if path.is_dir():
        return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())
    return path.stat().st_size


def write_recordings(root: Path, size_mb: float) -> dict[str, Path]:
    """The same recording in every format; its duration is chosen to give `size_mb` of scans."""
    from pipeline.io.writer import WriterFormat
    from tests.pipeline.io.recordings import Spec, write_recording

    scan_hz, lidars, stops = 10.0, 2, 16
    seconds = size_mb * 1e6 / (lidars * scan_hz * POINTS_PER_SCAN * BYTES_PER_POINT)
    cycle = seconds / stops
    spec = Spec(
        stops=stops,
        dwell_s=0.75 * cycle,
        move_s=0.25 * cycle,
        scan_hz=scan_hz,
        points=POINTS_PER_SCAN,
        float64_lidars=(),
        big_endian_lidars=(),
        turn_deg=22.5,
    )
    mcap, sqlite, ros1 = root / "bag_mcap", root / "bag_sqlite3", root / "bag.bag"
    write_recording(mcap, WriterFormat.ROS2_MCAP, spec)
    write_recording(sqlite, WriterFormat.ROS2_SQLITE3, spec)
    write_recording(ros1, WriterFormat.ROS1, spec)
    bare = root / "bare"
    bare.mkdir()
    paths = {
        "ROS 2 dir (MCAP)": mcap,
        "ROS 2 dir (sqlite3)": sqlite,
        "bare .mcap": Path(shutil.copy(mcap / "bag_mcap.mcap", bare / "bag.mcap")),
        "bare .db3": Path(shutil.copy(sqlite / "bag_sqlite3.db3", bare / "bag.db3")),
        "ROS 1 .bag": ros1,
    }
    with zipfile.ZipFile(root / "bag.zip", "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
        for file in sorted(mcap.iterdir()):
            zf.write(file, f"bag_mcap/{file.name}")
    paths[".zip (deflate)"] = root / "bag.zip"
    for mode, name, label in (("w", "bag.tar", ".tar"), ("w:gz", "bag.tar.gz", ".tar.gz")):
        with tarfile.open(root / name, mode) as tf:  # type: ignore[call-overload]
            tf.add(mcap, arcname="bag_mcap")
        paths[label] = root / name
    return paths


def measure(path: Path, repeat: int) -> dict[str, float]:
    """In this (fresh) process: best warm read time, traced peak, RSS peak over the baseline."""
    from pipeline.io import read_recording

    baseline_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    times, cpu_times = [], []
    for _ in range(repeat + 1):  # the first read warms the page cache and the imports
        start, cpu_start = time.perf_counter(), time.process_time()
        problem = read_recording(path)
        times.append(time.perf_counter() - start)
        cpu_times.append(time.process_time() - cpu_start)
        kept = problem.kept_points()
        del problem
    rss_peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    tracemalloc.start()
    problem = read_recording(path)
    _, traced_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {
        "seconds": min(times[1:]),
        "cpu_seconds": min(cpu_times[1:]),
        "kept_points": kept,
        "stops": len(problem.stops),
        "traced_peak": traced_peak,
        "rss_peak_over_baseline": (rss_peak_kb - baseline_kb) * 1024,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size-mb", type=float, default=100.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--measure", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.measure is not None:
        print(json.dumps(measure(args.measure, args.repeat)))
        return

    with tempfile.TemporaryDirectory(prefix="bench-io-") as tmp:
        start = time.perf_counter()
        paths = write_recordings(Path(tmp), args.size_mb)
        print(
            f"wrote {len(paths)} recordings in {time.perf_counter() - start:.1f} s", file=sys.stderr
        )
        load = " / ".join(f"{x:.1f}" for x in os.getloadavg())
        print(f"{os.cpu_count()} cores, load average {load} (1 / 5 / 15 min) before the reads\n")
        print(
            "| format | size MB | wall s | MB/s (wall) | CPU s | MB/s (CPU) | stops | kept points "
            "| kept MB | traced peak MB | traced / kept | RSS peak MB | RSS / kept |"
        )
        print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        for label, path in paths.items():
            out = subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "tests.bench.bench_io",
                    "--measure",
                    str(path),
                    "--repeat",
                    str(args.repeat),
                ],
                check=True,
                capture_output=True,
                text=True,
            ).stdout
            row = json.loads(out)
            size = _size(path) / 1e6
            kept = row["kept_points"] * 3 * 8 / 1e6
            traced, rss = row["traced_peak"] / 1e6, row["rss_peak_over_baseline"] / 1e6
            wall, cpu = row["seconds"], row["cpu_seconds"]
            print(
                f"| {label} | {size:.1f} | {wall:.3f} | {size / wall:.0f} | {cpu:.3f} "
                f"| {size / cpu:.0f} | {row['stops']} | {row['kept_points']:,} | {kept:.1f} "
                f"| {traced:.1f} | {traced / kept:.2f} | {rss:.1f} | {rss / kept:.2f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
