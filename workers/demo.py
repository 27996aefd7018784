"""`fleetcal demo`: the main job end to end on a fresh machine. It starts the embedded service,
synthesises a set-1 recording, uploads it through the API as a robot would, follows the run's
progress, prints the verdict and the calibrated extrinsics against the synthesiser's truth, and
leaves the service running (or, with `--once`, exits: 0 if the run passed)."""

from __future__ import annotations

import hashlib
import json
import tempfile
import threading
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from service.cli import DataDirOption, settings_for, startup_errors

if TYPE_CHECKING:
    import httpx

    from pipeline import Truth
    from service.settings import Settings

ROBOT_ID = "demo-1"
DEMO_SCENARIO = "set1-box"
DEMO_RATE_SCALE = 0.1
"""A tenth of the Mid-70's point rate: the whole demo stays within a minute or two on two cores."""
RUN_CONFIG = {"frames": {"base_height_above_floor_m": 0.0}}
"""The synthesiser's `base_link` lies on the floor (REP 105's base_footprint), so the floor gives
the reference LiDAR's height, roll and pitch too."""
POLL_S = 0.5
RUN_TIMEOUT_S = 900


def demo(
    once: Annotated[
        bool,
        typer.Option("--once", help="Exit after the verdict (status 0 only if the run passed)."),
    ] = False,
    data_dir: DataDirOption = None,
    host: Annotated[str, typer.Option("--host")] = "127.0.0.1",
    port: Annotated[
        int, typer.Option("--port", min=0, max=65535, help="0 or a busy port: any free one.")
    ] = 8000,
    scenario: Annotated[str, typer.Option("--scenario")] = DEMO_SCENARIO,
    rate_scale: Annotated[
        float, typer.Option("--rate-scale", min=0.01, max=1.0, help="LiDAR point rate factor.")
    ] = DEMO_RATE_SCALE,
    seed: Annotated[int, typer.Option("--seed")] = 0,
) -> None:
    """Run the main job end to end: embedded service, synthetic recording, upload, verdict."""
    from service.startup import where_state_lives  # pydantic: not for every `fleetcal` start
    from workers.admin_key import print_first_admin_key
    from workers.embedded import EmbeddedService, first_admin_key
    from workers.process import configure_logging, stop_signals

    started = time.monotonic()
    configure_logging("warning")
    settings = settings_for(data_dir)
    service = EmbeddedService(settings, host=host, port=_free_or_any(host, port), workers=1)
    with startup_errors():
        service.prepare(migrate=True)
    with service:
        _step(1, f"service   {service.url} ({where_state_lives(settings)})")
        print_first_admin_key(first_admin_key(settings), settings)
        robot_key = _robot_key(settings)
        with tempfile.TemporaryDirectory(prefix="fleetcal-demo-") as scratch:
            truth, archive = _synthesise(Path(scratch), scenario, seed, rate_scale)
            import httpx

            client = httpx.Client(
                base_url=service.url, headers={"X-API-Key": robot_key}, timeout=60
            )
            with client:
                run_id = _upload(client, archive)
                run = _follow(client, run_id)
        passed = _report(run, truth)
        typer.echo(f"demo took {time.monotonic() - started:.0f} s")
        if once:
            raise typer.Exit(0 if passed else 1)
        _serve_on(service.url, run_id, robot_key, settings)
        stop = threading.Event()
        with stop_signals(lambda now=False: stop.set()):
            stop.wait()


def _robot_key(settings: Settings) -> str:
    """A new upload key for the demo's robot (each demo run makes its own)."""
    from service.auth import create_key
    from service.db import Database
    from service.models import Scope

    db = Database.from_settings(settings)
    try:
        with db.transaction() as session:
            key = create_key(session, [Scope.UPLOAD], robot_id=ROBOT_ID, name="fleetcal demo")
    finally:
        db.dispose()
    return key.secret


def _step(number: int, text: str) -> None:
    typer.echo(f"[{number}/5] {text}")


def _synthesise(scratch: Path, scenario: str, seed: int, rate_scale: float) -> tuple[Truth, Path]:
    from pipeline import archive_recording, get_scenario, synthesise_recording

    spec = get_scenario(scenario)
    _step(2, f"synthesise {scenario}: {spec.description} ({rate_scale:.0%} of the point rate)")
    started = time.monotonic()
    out = scratch / "synth"
    truth = synthesise_recording(spec, out, seed=seed, rate_scale=rate_scale)
    archive = archive_recording(out, scratch / "recording.tar")
    size = archive.stat().st_size / 1e6
    typer.echo(f"          {time.monotonic() - started:.1f} s, {size:.1f} MB bag (tar)")
    return truth, archive


def _upload(client: httpx.Client, archive: Path) -> str:
    sha256 = hashlib.sha256()
    with archive.open("rb") as file:
        for chunk in iter(lambda: file.read(1 << 20), b""):
            sha256.update(chunk)

    def chunks() -> Iterator[bytes]:
        with archive.open("rb") as file:
            yield from iter(lambda: file.read(1 << 20), b"")

    started = time.monotonic()
    response = client.post(
        f"/v1/robots/{ROBOT_ID}/runs",
        params={"kind": "end_of_line"},
        content=chunks(),
        headers={
            "Content-Type": "application/octet-stream",
            "Content-Length": str(archive.stat().st_size),
            "X-Content-SHA256": sha256.hexdigest(),
            "Idempotency-Key": str(uuid.uuid4()),
            "X-Fleetcal-Config": json.dumps(RUN_CONFIG),
        },
    )
    if response.status_code != 202:
        typer.echo(f"error: upload refused ({response.status_code}): {response.text}", err=True)
        raise typer.Exit(2)
    run_id = str(response.json()["id"])
    _step(
        3,
        f"upload    run {run_id} for robot {ROBOT_ID} ({time.monotonic() - started:.1f} s),"
        f" {response.headers['Location']}",
    )
    return run_id


def _follow(client: httpx.Client, run_id: str) -> dict[str, Any]:
    """Poll the run as a robot would, printing each stage it enters, until it ends."""
    _step(4, "calibrate")
    started = time.monotonic()
    seen: str | None = None
    while True:
        run: dict[str, Any] = client.get(f"/v1/runs/{run_id}").raise_for_status().json()
        label = run["stage"] or run["status"]
        if label != seen:
            progress = f"{run['progress']:.0%}" if run["progress"] is not None else ""
            typer.echo(f"          {time.monotonic() - started:6.1f} s  {label:<18} {progress}")
            seen = label
        if run["status"] in ("succeeded", "failed"):
            return run
        if time.monotonic() - started > RUN_TIMEOUT_S:
            typer.echo(f"error: the run did not finish within {RUN_TIMEOUT_S} s", err=True)
            raise typer.Exit(2)
        time.sleep(POLL_S)


def _report(run: dict[str, Any], truth: Truth) -> bool:
    if run["status"] == "failed":
        _step(5, f"FAILED: {run['error']['title']}: {run['error']['detail']}")
        return False
    result = run["result"]
    verdict = result["verdict"]
    metric = result.get("metric_error", {})
    _step(
        5,
        f"verdict   {'PASSED' if verdict['passed'] else 'NOT PASSED'}; metric error "
        f"{_mm(metric.get('initial'))} -> {_mm(metric.get('final'))}",
    )
    for check in verdict["checks"]:
        if not check["passed"]:
            typer.echo(f"          failed check {check['name']}: {check.get('detail') or ''}")
    for line in extrinsics_table(result, truth):
        typer.echo(f"          {line}")
    return bool(verdict["passed"])


def extrinsics_table(result: dict[str, Any], truth: Truth) -> list[str]:
    """Calibrated `T_base_lidar` per LiDAR and its error against the truth.

    The data fix the LiDARs relative to each other and to the floor, not to the base: the error
    of each other LiDAR is taken relative to the reference (`T_ref_lidar`); the reference's own
    error shows what the floor fixed (height, roll, pitch) and what tf_static still holds.
    """
    import numpy as np
    from scipy.spatial.transform import Rotation

    from pipeline import from_translation_xyzw, invert, pose_difference

    def pose(entry: dict[str, Any]) -> np.ndarray:
        return from_translation_xyzw(entry["translation"], entry["rotation_xyzw"])

    reference = result["reference_frame"]
    lidars = result["lidars"]
    T_base_ref = {state: pose(lidars[reference][state]) for state in ("initial", "calibrated")}
    lines = [
        f"{'LiDAR':<14}{'x':>8}{'y':>8}{'z':>8}{'roll':>8}{'pitch':>8}{'yaw':>8}"
        f"   error vs truth: initial -> calibrated",
        f"{'':<14}{'m':>8}{'m':>8}{'m':>8}{'deg':>8}{'deg':>8}{'deg':>8}",
    ]
    for frame, lidar in sorted(lidars.items(), key=lambda item: item[0] != reference):
        if lidar.get("calibrated") is None:
            lines.append(f"{frame:<14}undetermined by the data")
            continue
        T = pose(lidar["calibrated"])
        x, y, z = T[:3, 3]
        roll, pitch, yaw = Rotation.from_matrix(T[:3, :3]).as_euler("xyz", degrees=True)
        true = truth.lidar(frame).T_base_lidar_true
        if frame == reference:
            errors = [pose_difference(pose(lidar[s]), true) for s in ("initial", "calibrated")]
            what = "T_base_lidar (x, y, yaw from tf_static)"
        else:
            true_rel = truth.T_ref_lidar_true(frame)
            errors = [
                pose_difference(invert(T_base_ref[s]) @ pose(lidar[s]), true_rel)
                for s in ("initial", "calibrated")
            ]
            what = f"relative to {reference}"
        (t0, r0), (t1, r1) = errors
        marker = "*" if frame == reference else " "
        lines.append(
            f"{frame + marker:<14}{x:8.3f}{y:8.3f}{z:8.3f}{roll:8.2f}{pitch:8.2f}{yaw:8.2f}"
            f"   {t0 * 1000:6.1f} mm {r0:5.2f} deg -> {t1 * 1000:5.1f} mm {r1:5.3f} deg ({what})"
        )
    lines.append("* reference LiDAR")
    return lines


def _serve_on(url: str, run_id: str, robot_key: str, settings: Settings) -> None:
    from workers.admin_key import keys_create_hint

    typer.echo("")
    typer.echo(f"The service keeps running at {url} (API docs: {url}/docs); Ctrl-C stops it.")
    typer.echo(
        f"  the dashboard:    {url}/#/runs/{run_id} (sign in with the admin key printed on the "
        f"first start, or a key from `{keys_create_hint(settings)}`)"
    )
    typer.echo(f"  the run:          curl -H 'X-API-Key: {robot_key}' {url}/v1/runs/{run_id}")
    typer.echo(
        f"  the calibration:  curl -H 'X-API-Key: {robot_key}' "
        f"{url}/v1/robots/{ROBOT_ID}/calibration"
    )


def _mm(value: float | None) -> str:
    return "n/a" if value is None else f"{value * 1000:.1f} mm"


def _free_or_any(host: str, port: int) -> int:
    """`port` if it is free, else 0 (the system picks one): a demo must not fail on a busy port."""
    import socket

    if port == 0:
        return 0
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as probe:
        try:
            probe.bind((host, port))
        except OSError:
            return 0
    return port
