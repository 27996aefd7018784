"""The pipeline config of a run: the upload's config with the verdict's limits from the robot's
tolerance profile; an upload cannot set (loosen) its own verdict."""

from __future__ import annotations

import itertools
import tarfile
import tempfile
from pathlib import Path

import pytest

from pipeline.config import PipelineConfig
from pipeline.errors import ConfigError
from pipeline.io.errors import CorruptRecordingError, UnknownFormatError
from service.settings import Settings
from service.storage import make_storage
from workers.context import JobSpec
from workers.job import calibrate_run, pipeline_config_for, without_scratch_paths


def test_the_profile_sets_the_verdict_and_the_upload_the_rest() -> None:
    limits = {
        "max_metric_error_m": 0.02,
        "max_seen_metric_error_m": 0.01,
        "max_rotation_stddev_deg": 0.3,
        "max_translation_drift_m": 0.01,
    }
    config = pipeline_config_for({"frames": {"reference_frame": "lidar_rear"}}, limits)
    assert config.frames.reference_frame == "lidar_rear"
    assert config.verdict.max_metric_error_m == 0.02
    assert config.verdict.max_seen_metric_error_m == 0.01
    assert config.verdict.max_rotation_stddev_deg == 0.3
    default = PipelineConfig().verdict
    assert config.verdict.max_translation_stddev_m == default.max_translation_stddev_m
    unset = pipeline_config_for(None, {}).verdict
    assert unset.max_metric_error_m is None  # eq. 12 is checked only where a profile sets it
    assert unset.max_seen_metric_error_m == default.max_seen_metric_error_m


def test_an_upload_cannot_set_its_verdict() -> None:
    with pytest.raises(ConfigError, match="tolerance profile"):
        pipeline_config_for({"verdict": {"max_metric_error_m": 10.0}}, {})


def test_an_unknown_setting_is_a_config_error_naming_it() -> None:
    with pytest.raises(ConfigError, match=r"optimisation\.max_iteration"):
        pipeline_config_for({"optimisation": {"max_iteration": 5}}, {})


def test_a_bad_recording_is_reported_without_the_worker_s_temporary_paths(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("garbage: [\n")
    archive = tmp_path / "upload.tar"
    with tarfile.open(archive, "w") as tar:
        tar.add(bag, arcname="bag")
    settings = Settings(data_dir=tmp_path / "state")
    pending = make_storage(settings).begin_upload("recordings/R1/run-1")
    pending.write(archive.read_bytes())
    pending.commit()
    spec = JobSpec(
        run_id="run-1",
        attempt=1,
        robot_id="R1",
        kind="end_of_line",
        storage_key="recordings/R1/run-1",
        upload_format="tar",
        config=None,
        settings=settings,
    )
    with pytest.raises(CorruptRecordingError) as refused:
        calibrate_run(spec, lambda stage, progress: None)
    message = str(refused.value)
    assert message.startswith("bag/metadata.yaml cannot be read (while parsing")
    assert "fleetcal-" not in message and tempfile.gettempdir() not in message


def test_the_uploaded_recording_replaces_its_scratch_path(tmp_path: Path) -> None:
    recording = Path(tempfile.gettempdir()) / "fleetcal-run-abc123" / "recording.tar"
    err = without_scratch_paths(
        UnknownFormatError(f"{recording} holds no recording; archive the bag directory"), recording
    )
    assert str(err) == "the uploaded recording holds no recording; archive the bag directory"


def test_optimisation_progress_moves_at_every_iteration_and_stays_in_its_stage() -> None:
    from workers.job import _STAGE_PROGRESS, optimisation_progress

    values = [optimisation_progress(k, 200) for k in range(0, 201)]
    assert values[0] == _STAGE_PROGRESS["optimisation"]
    assert all(b > a for a, b in itertools.pairwise(values))
    assert values[-1] == _STAGE_PROGRESS["metric"]
    # A typical run converges in tens of iterations: by then most of the stage's share is shown.
    assert values[30] > _STAGE_PROGRESS["optimisation"] + 0.8 * (
        _STAGE_PROGRESS["metric"] - _STAGE_PROGRESS["optimisation"]
    )
