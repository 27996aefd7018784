import json
import math
import typing

import jsonschema
import numpy as np
import pytest
from pydantic import ValidationError

from pipeline.observability import DOF_NAMES
from pipeline.result import result_document
from pipeline.result_model import (
    SCHEMA_FILE,
    Dof,
    PoseResult,
    ResultDocument,
    main,
    result_schema,
    rpy_deg,
    schema_text,
)
from tests.pipeline.calibration_data import box_calibration, floor_only_calibration


def test_the_committed_schema_is_the_generated_one() -> None:
    assert SCHEMA_FILE.read_text(encoding="utf-8") == schema_text(), (
        "pipeline/result_schema.json is out of date: run python -m pipeline.result_model"
    )
    assert main(["--check"]) == 0


def test_the_check_fails_on_a_stale_schema(monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:  # type: ignore[no-untyped-def]
    stale = tmp_path / "result_schema.json"
    stale.write_text("{}\n", encoding="utf-8")
    monkeypatch.setattr("pipeline.result_model.SCHEMA_FILE", stale)
    assert main(["--check"]) == 1
    assert main([]) == 0
    assert stale.read_text(encoding="utf-8") == schema_text()


def test_the_schema_keeps_the_contract_fields_required() -> None:
    schema = result_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert set(schema["required"]) == {
        "schema_version",
        "reference_frame",
        "base_frame",
        "lidars",
        "metric_error",
        "verdict",
        "stages",
        "pipeline_version",
        "config_hash",
    }
    lidar = schema["$defs"]["LidarResult"]
    assert set(lidar["required"]) == {"topic", "initial", "calibrated", "stddev"}
    assert "rpy_deg" not in json.dumps(schema), "result.json holds no computed fields"


def test_the_dof_names_are_the_observability_ones() -> None:
    assert typing.get_args(Dof) == DOF_NAMES


@pytest.mark.parametrize("calibration", [box_calibration, floor_only_calibration])
def test_a_document_survives_the_service_unchanged(calibration) -> None:  # type: ignore[no-untyped-def]
    """The service validates what the worker wrote and returns it: the same data, plus angles."""
    document = result_document(calibration(), read_seconds=0.5)
    parsed = ResultDocument.model_validate(document)
    assert parsed.model_dump(mode="json", exclude_computed_fields=True) == document
    returned = parsed.model_dump(mode="json")
    rear = returned["lidars"]["lidar_rear"]
    assert rear["initial"]["rpy_deg"] == pytest.approx(
        list(rpy_deg(tuple(document["lidars"]["lidar_rear"]["initial"]["rotation_xyzw"])))
    )
    assert "rpy_deg" not in json.dumps(document)


def _rpy_by_hand(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """Roll, pitch, yaw (deg) of R = Rz(yaw) Ry(pitch) Rx(roll), from the quaternion directly."""
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return math.degrees(roll), math.degrees(pitch), math.degrees(yaw)


def test_rpy_is_fixed_axis_roll_pitch_yaw() -> None:
    rng = np.random.default_rng(7)
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        expected = _rpy_by_hand(*q.tolist())
        assert rpy_deg((q[0], q[1], q[2], q[3])) == pytest.approx(expected, abs=1e-9)
    yaw_90 = PoseResult(translation=(0, 0, 0), rotation_xyzw=(0, 0, math.sqrt(0.5), math.sqrt(0.5)))
    assert yaw_90.rpy_deg == pytest.approx((0.0, 0.0, 90.0))


@pytest.mark.parametrize(
    ("rotation", "field"),
    [((0.0, 0.0, 0.0, 0.0), "has no direction"), ((0.0, 0.0, 0.0, 1.5), "less than or equal")],
)
def test_a_pose_needs_a_unit_quaternion(rotation: tuple[float, ...], field: str) -> None:
    with pytest.raises(ValidationError, match=field):
        PoseResult.model_validate({"translation": [0, 0, 0], "rotation_xyzw": list(rotation)})


def test_fields_of_later_versions_are_kept() -> None:
    document = result_document(box_calibration())
    document["lidars"]["lidar_rear"]["temperature_c"] = 41.5
    document["verdict"]["checks"][0]["unit"] = "m"
    dumped = ResultDocument.model_validate(document).model_dump(
        mode="json", exclude_computed_fields=True
    )
    assert dumped["lidars"]["lidar_rear"]["temperature_c"] == 41.5
    assert dumped["verdict"]["checks"][0]["unit"] == "m"


def test_nan_is_refused() -> None:
    document = result_document(box_calibration())
    document["metric_error"]["final"] = float("nan")
    with pytest.raises(ValidationError, match="finite"):
        ResultDocument.model_validate(document)
