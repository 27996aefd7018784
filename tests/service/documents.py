"""A realistic `result.json` (`pipeline.result_model.ResultDocument`) for the data layer and API
tests; `test_repository` holds it to the model."""

from __future__ import annotations

from typing import Any


def result_document(
    *, passed: bool = True, final: float = 0.0012, rear_x: float = -0.41
) -> dict[str, Any]:
    """Three LiDARs: the reference, one calibrated, one the data could not determine."""
    return {
        "schema_version": 1,
        "reference_frame": "lidar_front",
        "base_frame": "base_link",
        "lidars": {
            "lidar_front": _reference_lidar(),
            "lidar_rear": _calibrated_lidar(rear_x),
            "lidar_left": _undetermined_lidar(),
        },
        "metric_error": {"initial": 0.021, "final": final},
        "verdict": {
            "passed": passed,
            "checks": [
                {"name": "metric_error", "value": final, "limit": 0.005, "passed": final <= 0.005},
                {"name": "lidar_left determined", "value": None, "limit": None, "passed": False},
            ],
        },
        "stages": {
            "denoise": {"seconds": 0.41, "removed_points": 1234},
            "segment": {"seconds": 0.9},
            "rough": {"seconds": 1.7},
            "joint": {"seconds": 6.2, "iterations": 38},
        },
        "pipeline_version": "0.1.0",
        "config_hash": "sha256:" + "ab" * 32,
    }


def _reference_lidar() -> dict[str, Any]:
    """The reference LiDAR: calibrated where it started, without uncertainty."""
    return {
        "topic": "/lidar_front/points",
        "initial": {"translation": [0.45, 0.0, 0.62], "rotation_xyzw": [0, 0, 0, 1]},
        "calibrated": {
            "translation": [0.45, 0.0, 0.62],
            "rotation_xyzw": [0.0, 0.0, 0.0, 1.0],
        },
        "stddev": {"translation_m": [0, 0, 0], "rotation_deg": [0, 0, 0]},
    }


def _calibrated_lidar(x: float) -> dict[str, Any]:
    """The rear LiDAR, calibrated at `x` (m) behind the base."""
    return {
        "topic": "/lidar_rear/points",
        "initial": {
            "translation": [-0.5, 0.02, 0.6],
            "rotation_xyzw": [0.0, 0.0, 0.9999619, 0.0087265],
        },
        "calibrated": {
            "translation": [x, 0.004, 0.618],
            "rotation_xyzw": [0.0012, -0.0008, 0.9999985, 0.0009],
        },
        "stddev": {
            "translation_m": [0.0011, 0.0009, 0.0014],
            "rotation_deg": [0.02, 0.03, 0.01],
        },
    }


def _undetermined_lidar() -> dict[str, Any]:
    """The left LiDAR, which saw only the floor."""
    return {
        "topic": "/lidar_left/points",
        "initial": {
            "translation": [0.0, 0.3, 0.6],
            "rotation_xyzw": [0, 0, 0.7071, 0.7071],
        },
        "calibrated": None,  # floor only: no object constrains x, y and yaw
        "stddev": {
            "translation_m": [None, None, 0.0021],
            "rotation_deg": [0.03, 0.04, None],
        },
        "undetermined": ["x", "y", "yaw"],
    }
