"""`fleetcal upload`'s flow: send the recording once (whatever the retries), then optionally
follow the run until it ends and say its verdict and how the extrinsics changed."""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from client.api import Api
from client.errors import (
    EXIT_FAILED_VERDICT,
    EXIT_PASSED,
    EXIT_REFUSED,
    BadInputError,
    UnreachableError,
)
from client.payload import Payload, idempotency_key
from client.progress import Progress

FINAL_STATUSES = ("succeeded", "failed")


@dataclass(frozen=True)
class Uploaded:
    run: dict[str, Any]
    replayed: bool


def load_config(path: Path | None) -> dict[str, Any] | None:
    """The run config (`X-Fleetcal-Config`) from a YAML or JSON file."""
    if path is None:
        return None
    import yaml

    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
        raise BadInputError(f"cannot read the config {path} ({err})") from None
    if not isinstance(data, dict):
        raise BadInputError(
            f"the config {path} must be a mapping (reference LiDAR, extrinsics, ...)"
        )
    return data


def upload(
    api: Api,
    payload: Payload,
    *,
    robot: str,
    kind: str,
    config: Mapping[str, Any] | None,
    progress: Progress,
) -> Uploaded:
    """POST the recording; a retry re-sends it with the same key, so there is one run at most."""
    headers = {
        "Idempotency-Key": idempotency_key(payload, kind, config),
        "X-Content-SHA256": payload.sha256,
        "Content-Length": str(payload.size),
        "Content-Type": "application/octet-stream",
    }
    if config:
        headers["X-Fleetcal-Config"] = json.dumps(config, separators=(",", ":"))

    def body() -> Any:
        progress.restart()
        return payload.chunks(progress.advance)

    response = api.request(
        "POST",
        f"/v1/robots/{robot}/runs",
        ok=(200, 201, 202),
        params={"kind": kind},
        headers=headers,
        content=body,
    )
    return Uploaded(response.json(), response.headers.get("Idempotent-Replayed") == "true")


def wait_for_run(
    api: Api,
    run_id: str,
    *,
    say: Callable[[str], None],
    poll_s: float = 1.0,
    timeout_s: float = 3600.0,
) -> dict[str, Any]:
    """Poll the run until it ends; each new stage or progress step is said once."""
    deadline = time.monotonic() + timeout_s
    last: tuple[Any, ...] = ()
    while True:
        run: dict[str, Any] = api.json("GET", f"/v1/runs/{run_id}")
        now = (run.get("status"), run.get("stage"), run.get("progress"))
        if now != last:
            last = now
            share = f" {100 * now[2]:.0f}%" if isinstance(now[2], int | float) else ""
            say(f"run {run_id}: {now[0]}" + (f", {now[1]}" if now[1] else "") + share)
        if run.get("status") in FINAL_STATUSES:
            return run
        if time.monotonic() > deadline:
            raise UnreachableError(
                f"run {run_id} has not finished after {timeout_s:.0f} s (still {now[0]}); "
                f"follow it with `fleetcal runs show {run_id}`"
            )
        time.sleep(poll_s)


def outcome(run: Mapping[str, Any]) -> tuple[int, list[str]]:
    """The exit code and the lines that explain it: verdict, failed checks, changed extrinsics."""
    result = run.get("result")
    if run.get("status") != "succeeded" or not isinstance(result, Mapping):
        error = run.get("error") or {}
        return EXIT_REFUSED, [
            f"FAILED: run {run.get('id')} ended {run.get('status')} after "
            f"{run.get('attempts')} attempt(s): {error.get('detail') or error.get('title')}"
        ]
    passed = bool(result.get("verdict", {}).get("passed"))
    metric = result.get("metric_error") or {}
    lines = [
        f"{'PASSED' if passed else 'FAILED'}: metric error {_mm(metric.get('initial'))} -> "
        f"{_mm(metric.get('final'))}"
    ]
    for check in result.get("verdict", {}).get("checks", []):
        if not check.get("passed", True):
            lines.append(
                f"  failed check {check.get('name')}: {check.get('value')} "
                f"over {check.get('limit')}"
            )
    lines += extrinsic_changes(result)
    return (EXIT_PASSED if passed else EXIT_FAILED_VERDICT), lines


def extrinsic_changes(result: Mapping[str, Any]) -> list[str]:
    """Per LiDAR: calibrated `T_base_lidar` (x y z m, roll pitch yaw deg) and its change."""
    from scipy.spatial.transform import Rotation

    base = result.get("base_frame", "base")
    lines = []
    for frame, lidar in sorted((result.get("lidars") or {}).items()):
        calibrated, initial = lidar.get("calibrated"), lidar.get("initial")
        if not calibrated:
            lines.append(f"  T_{base}_{frame}: undetermined by the data (kept as it was)")
            continue
        R_after = Rotation.from_quat(calibrated["rotation_xyzw"])
        rpy = R_after.as_euler("xyz", degrees=True)
        xyz = calibrated["translation"]
        text = (
            f"  T_{base}_{frame}: xyz [{', '.join(f'{v:.4f}' for v in xyz)}] m, "
            f"rpy [{', '.join(f'{v:.3f}' for v in rpy)}] deg"
        )
        if initial:
            moved = sum((a - b) ** 2 for a, b in zip(xyz, initial["translation"], strict=True))
            turned = (Rotation.from_quat(initial["rotation_xyzw"]).inv() * R_after).magnitude()
            text += f"; changed {1000 * moved**0.5:.1f} mm, {float(turned) * 57.29578:.3f} deg"
        lines.append(text)
    return lines


def _mm(value: Any) -> str:
    return f"{1000 * value:.2f} mm" if isinstance(value, int | float) else "?"
