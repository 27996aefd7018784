import json

import jsonschema
import pytest

from pipeline.result import dumps, result_document, result_schema
from pipeline.result_model import ResultDocument
from tests.pipeline.calibration_data import (
    box_calibration,
    dense_box_calibration,
    floor_only_calibration,
)


@pytest.mark.parametrize("calibration", [box_calibration, floor_only_calibration])
def test_result_json_satisfies_the_schema(calibration) -> None:  # type: ignore[no-untyped-def]
    document = json.loads(dumps(calibration(), read_seconds=0.5))
    jsonschema.Draft202012Validator(result_schema()).validate(document)
    assert set(document["lidars"]) == {"lidar_front", "lidar_rear"}
    assert document["stages"]["read"]["seconds"] == 0.5
    assert document["stages"]["denoise"]["removed_points"] >= 0


def test_the_contract_fields_of_a_passed_calibration() -> None:
    result = dense_box_calibration()
    document = result_document(result)
    assert document["schema_version"] == 1
    assert document["reference_frame"] == "lidar_front"
    assert document["base_frame"] == "base_link"
    assert document["verdict"]["passed"] is True
    assert document["config_hash"] == result.config_hash
    rear = document["lidars"]["lidar_rear"]
    assert rear["calibrated"]["translation"] == pytest.approx(
        result.lidar("lidar_rear").T_base_lidar_calibrated[:3, 3].tolist()
    )
    assert len(rear["stddev"]["translation_m"]) == 3


def test_an_undetermined_lidar_has_no_calibrated_pose_and_no_confident_stddev() -> None:
    document = result_document(floor_only_calibration())
    rear = document["lidars"]["lidar_rear"]
    assert rear["calibrated"] is None
    assert rear["undetermined"] == ["x", "y", "yaw"]
    assert rear["stddev"]["translation_m"][:2] == [None, None]
    assert rear["stddev"]["rotation_deg"][2] is None
    assert document["metric_error"]["final"] is None  # no object points: nothing to compare
    determined = [c for c in document["verdict"]["checks"] if c["name"] == "determined:lidar_rear"]
    assert determined[0]["passed"] is False and determined[0]["dofs"] == ["x", "y", "yaw"]


def test_the_keys_are_in_contract_order() -> None:
    document = result_document(floor_only_calibration(), read_seconds=0.5)
    assert list(document) == [key for key in ResultDocument.model_fields if key in document]
    assert list(document["lidars"]["lidar_rear"])[:5] == [
        "topic",
        "reference",
        "initial",
        "calibrated",
        "stddev",
    ]
    assert next(iter(document["stages"])) == "read"
    passed = [c for c in document["verdict"]["checks"] if c["passed"]]
    assert all(set(c) == {"name", "value", "limit", "passed"} for c in passed), "no empty detail"
    assert "drift" not in document and "tolerance_profile" not in document
