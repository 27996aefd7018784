"""`fleetcal upload` against a real `fleetcal serve`: one run whatever the retries (the service
SIGKILLed mid-upload and restarted), exit codes, and --wait's verdict on a real calibration."""

from __future__ import annotations

import io
import threading
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from client.api import Api
from client.errors import RefusedError
from client.payload import payload_for
from client.progress import Progress
from client.upload import upload
from tests.client.conftest import ROBOT, Served, free_port, prepared
from workers.cli import app

MCAP_MAGIC = b"\x89MCAP0\r\n"


def fake_mcap(path: Path, size: int) -> Path:
    """Bytes the service accepts as an upload (MCAP magic first); never calibrated here."""
    path.write_bytes(MCAP_MAGIC + bytes(range(256)) * (size // 256))
    return path


class KillingProgress(Progress):
    """Progress that SIGKILLs the service once a quarter of the body is sent, then restarts it."""

    def __init__(self, total: int, served: Served) -> None:
        super().__init__(total, stream=io.StringIO(), tty=False)
        self.served = served
        self.killed = threading.Event()
        self.restarter: threading.Thread | None = None

    def advance(self, n: int) -> None:
        super().advance(n)
        if not self.killed.is_set() and self.sent > self.total // 4:
            self.killed.set()
            self.served.kill()
            self.restarter = threading.Thread(target=self.served.start)
            self.restarter.start()


def cli(*args: str) -> Any:
    return CliRunner().invoke(app, list(args))


def upload_cli(served: Served, recording: Path, robot: str = ROBOT, *extra: str) -> Any:
    """`fleetcal upload RECORDING` for `robot` with the upload key, kind end_of_line."""
    return cli(
        "upload",
        str(recording),
        "--url",
        served.url,
        "--key",
        served.upload_key,
        "--robot",
        robot,
        "--kind",
        "end_of_line",
        *extra,
    )


@pytest.mark.slow
def test_service_killed_mid_upload_and_restarted_ends_with_one_run(
    api_only: Served, tmp_path: Path
) -> None:
    recording = fake_mcap(tmp_path / "big.mcap", 24 * 1024 * 1024)
    payload = payload_for(recording)
    progress = KillingProgress(payload.size, api_only)
    api = Api(
        api_only.url,
        api_only.upload_key,
        # Enough retries to outlast a restart on a loaded machine (about 90 s at most).
        retries=30,
        backoff_s=0.3,
        max_backoff_s=3,
        on_retry=progress.line,
    )

    sent = upload(api, payload, robot=ROBOT, kind="end_of_line", config=None, progress=progress)

    assert progress.killed.is_set() and progress.restarter is not None
    progress.restarter.join()
    assert isinstance(progress.stream, io.StringIO)
    assert "retrying" in progress.stream.getvalue()
    assert not sent.replayed
    assert [run["id"] for run in api_only.runs()] == [sent.run["id"]]
    assert sent.run["upload"]["sha256"] == payload.sha256

    # The whole command run again (an operator's retry): the same run, still one.
    again = upload_cli(api_only, recording, ROBOT)
    assert again.exit_code == 0, again.output
    assert sent.run["id"] in again.stdout and "already uploaded" in again.output
    assert len(api_only.runs()) == 1


def test_another_kind_of_the_same_recording_is_a_second_run(
    api_only: Served, tmp_path: Path
) -> None:
    recording = fake_mcap(tmp_path / "r.mcap", 4096)
    common = ("--url", api_only.url, "--key", api_only.upload_key, "--robot", ROBOT)
    first = cli("upload", str(recording), *common, "--kind", "end_of_line")
    second = cli("upload", str(recording), *common, "--kind", "maintenance")
    assert first.exit_code == 0 and second.exit_code == 0, second.output
    assert len(api_only.runs()) == 2


def test_a_refused_upload_exits_2_with_the_problem(api_only: Served, tmp_path: Path) -> None:
    recording = fake_mcap(tmp_path / "r.mcap", 4096)
    result = upload_cli(api_only, recording, "OTHER")
    assert result.exit_code == 2
    assert "HTTP 403" in result.output and "OTHER" in result.output
    with pytest.raises(RefusedError, match="HTTP 401"):
        Api(api_only.url, "wrong-key").json("GET", "/v1/runs")
    assert api_only.runs() == []


def test_a_body_that_is_no_recording_exits_2(api_only: Served, tmp_path: Path) -> None:
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not a recording at all" * 100)
    result = upload_cli(api_only, junk, ROBOT)
    assert result.exit_code == 2 and "HTTP 415" in result.output, result.output


def test_an_unreachable_service_exits_3_after_its_retries(tmp_path: Path) -> None:
    recording = fake_mcap(tmp_path / "r.mcap", 4096)
    result = cli(
        "upload",
        str(recording),
        "--url",
        f"http://127.0.0.1:{free_port()}",
        "--key",
        "k",
        "--robot",
        ROBOT,
        "--kind",
        "end_of_line",
        "--retries",
        "2",
        "--backoff",
        "0",
    )
    assert result.exit_code == 3
    assert result.output.count("retrying") == 2 and "gave up after 3 attempts" in result.output


def test_a_missing_recording_exits_2(tmp_path: Path) -> None:
    result = cli("upload", str(tmp_path / "nope"), "--robot", ROBOT, "--kind", "end_of_line")
    assert result.exit_code == 2 and "does not exist" in result.output


@pytest.mark.slow
def test_wait_prints_the_verdict_and_the_extrinsics_of_a_real_calibration(
    tmp_path: Path,
) -> None:
    from pipeline.synth import write_recording
    from pipeline.synth.recording import RECORDING_DIR

    write_recording("tiny", tmp_path / "synth", seed=0)
    served = prepared(tmp_path / "data", workers=1)
    served.start()
    try:
        profile = tmp_path / "profile.yaml"
        profile.write_text(
            "is_default: true\nlimits:\n  max_metric_error_m: 0.5\n"
            "  max_translation_stddev_m: 1.0\n  max_rotation_stddev_deg: 10.0\n"
        )
        assert (
            cli(
                "profiles",
                "set",
                "wide",
                str(profile),
                "--url",
                served.url,
                "--key",
                served.admin_key,
            ).exit_code
            == 0
        )
        result = cli(
            "upload",
            str(tmp_path / "synth" / RECORDING_DIR),
            "--url",
            served.url,
            "--key",
            served.upload_key,
            "--robot",
            ROBOT,
            "--kind",
            "end_of_line",
            "--wait",
        )
    finally:
        served.stop()
    assert result.exit_code in (0, 1), result.output
    verdict = "PASSED" if result.exit_code == 0 else "FAILED"
    assert f"{verdict}: metric error" in result.stdout
    assert "T_base_link_lidar_" in result.stdout and "changed" in result.stdout
    assert "succeeded" in result.output
