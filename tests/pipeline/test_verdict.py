import math

import pytest

from pipeline.verdict import (
    DriftEvidence,
    LidarEvidence,
    StartsEvidence,
    Verdict,
    VerdictConfig,
    judge,
    with_drift,
)


def _lidar(frame: str, **changes: object) -> LidarEvidence:
    values: dict[str, object] = {
        "frame": frame,
        "is_reference": False,
        "object_points": 5000,
        "stddev_translation_m": (0.001, 0.001, 0.0005),
        "stddev_rotation_deg": (0.01, 0.01, 0.02),
        "undetermined": (),
        "deviation_translation_m": 0.05,
        "deviation_rotation_deg": 1.0,
        "seen_metric_error_m": 0.003,
        "seen_points": 4000,
    }
    values.update(changes)
    return LidarEvidence(**values)  # type: ignore[arg-type]


def test_a_good_calibration_passes_every_check() -> None:
    verdict = judge(
        0.004, True, 30, 200, [_lidar("a", is_reference=True), _lidar("b")], VerdictConfig()
    )
    assert verdict.passed
    names = [check.name for check in verdict.checks]
    assert names[0] == "convergence"
    assert "metric_error" not in names  # eq. 12 itself is checked only where a limit is set
    assert "determined:b" in names and "determined:a" not in names
    assert "seen_metric_error:b" in names and "seen_metric_error:a" not in names
    assert not any(name.startswith("deviation") for name in names)


def test_each_failure_is_a_named_check_with_value_and_limit() -> None:
    config = VerdictConfig(max_deviation_translation_m=0.02, max_metric_error_m=0.04)
    lidars = [
        _lidar("a", is_reference=True),
        _lidar("b", undetermined=("x", "y", "yaw"), object_points=0, seen_metric_error_m=0.03),
    ]
    verdict = judge(0.05, False, 200, 200, lidars, config)
    failed = {check.name: check for check in verdict.failed}
    assert not verdict.passed
    assert set(failed) == {
        "metric_error",
        "convergence",
        "object_points:b",
        "determined:b",
        "deviation_translation:b",
        "seen_metric_error:b",
    }
    assert "0.0300 m" in failed["seen_metric_error:b"].detail
    assert failed["determined:b"].dofs == ("x", "y", "yaw")
    assert "x, y, yaw" in failed["determined:b"].detail
    assert failed["metric_error"].value == 0.05
    assert failed["metric_error"].limit == config.max_metric_error_m


def test_a_nan_value_never_passes() -> None:
    config = VerdictConfig(max_metric_error_m=0.04)
    lidars = [_lidar("a", is_reference=True), _lidar("b", seen_metric_error_m=math.nan)]
    verdict = judge(math.nan, True, 3, 200, lidars, config)
    assert [c.name for c in verdict.failed] == ["metric_error", "seen_metric_error:b"]


def test_a_lidar_the_reference_saw_too_little_of_fails_the_seen_metric_saying_why() -> None:
    lidars = [
        _lidar("a", is_reference=True),
        _lidar("b", seen_metric_error_m=0.001, seen_points=40),
    ]
    verdict = judge(0.05, True, 3, 200, lidars, VerdictConfig(min_seen_points=100))
    (check,) = verdict.failed
    assert check.name == "seen_metric_error:b" and math.isnan(check.value)
    assert "40 of b's object points" in check.detail and "100 needed" in check.detail


def test_a_seen_metric_limit_of_none_skips_its_check() -> None:
    lidars = [_lidar("a", is_reference=True), _lidar("b", seen_metric_error_m=0.09)]
    verdict = judge(0.05, True, 3, 200, lidars, VerdictConfig(max_seen_metric_error_m=None))
    assert verdict.passed
    assert not any(c.name.startswith("seen_metric_error") for c in verdict.checks)


def _good() -> Verdict:
    lidars = [_lidar("a", is_reference=True), _lidar("b"), _lidar("c")]
    return judge(0.004, True, 30, 200, lidars, VerdictConfig())


def test_drift_is_judged_with_the_pipeline_checks_in_frame_order() -> None:
    drift = DriftEvidence(
        "last_accepted",
        {"c": (0.004, 0.2), "b": (0.03, 0.1)},
        max_translation_m=0.01,
        max_rotation_deg=0.5,
    )
    verdict = with_drift(_good(), drift)
    assert verdict.checks[: len(_good().checks)] == _good().checks
    added = verdict.checks[len(_good().checks) :]
    assert [c.name for c in added] == [
        "drift_translation:b",
        "drift_rotation:b",
        "drift_translation:c",
        "drift_rotation:c",
    ]
    assert not verdict.passed
    assert [c.name for c in verdict.failed] == ["drift_translation:b"]
    assert verdict.failed[0].detail == (
        "b is 0.03 m away from its last accepted calibration (limit 0.01 m): "
        "has its mount moved or been hit?"
    )
    assert verdict.evidence is not None and verdict.evidence.drift == drift


def test_drift_within_limits_keeps_the_verdict_passed() -> None:
    drift = DriftEvidence("design", {"b": (0.004, 0.2)}, max_rotation_deg=0.5)
    verdict = with_drift(_good(), drift)
    assert verdict.passed
    assert [c.name for c in verdict.checks[len(_good().checks) :]] == ["design_rotation:b"]


def test_without_limits_drift_is_evidence_but_no_check() -> None:
    drift = DriftEvidence("design", {"b": (0.5, 30.0)}, missing=("d",))
    assert with_drift(_good(), drift).checks == _good().checks


def test_a_lidar_the_reference_knows_but_the_run_did_not_calibrate_fails() -> None:
    drift = DriftEvidence("design", {"b": (0.0, 0.0)}, missing=("a2",), max_translation_m=0.02)
    failed = with_drift(_good(), drift).failed
    assert [c.name for c in failed] == ["design_missing:a2"]
    assert math.isnan(failed[0].value) and math.isnan(failed[0].limit)
    assert failed[0].detail == "a2 is in the design extrinsics but was not calibrated"


def test_a_verdict_made_without_judge_cannot_take_drift() -> None:
    with pytest.raises(ValueError, match="judge it anew"):
        with_drift(Verdict(True, ()), DriftEvidence("design", {}))


@pytest.mark.parametrize(
    ("apart_m", "apart_deg", "sigmas", "passed"),
    [
        (0.002, 0.05, 0.0, True),  # both starts ended as one calibration
        (1.2, 0.04, 3.2, True),  # apart, but the maps prefer the kept one decisively
        (3.5, 9.1, 0.8, False),  # apart, and the maps cannot tell them apart
        (0.004, 0.5, 1.0, False),  # a rotation apart is as ambiguous as a translation
    ],
)
def test_two_starts_that_end_apart_must_be_told_apart_by_the_maps(
    apart_m: float, apart_deg: float, sigmas: float, passed: bool
) -> None:
    lidars = [_lidar("a", is_reference=True), _lidar("b")]
    starts = StartsEvidence(apart_m, apart_deg, sigmas)
    verdict = judge(0.004, True, 30, 200, lidars, VerdictConfig(), starts=starts)
    check = next(c for c in verdict.checks if c.name == "unique_solution")
    assert check.passed is passed and verdict.passed is passed
    assert (check.value, check.limit) == (sigmas, VerdictConfig().min_start_separation_sigmas)
    if not passed:
        assert f"{apart_m:.3f} m" in check.detail and "record again" in check.detail


def test_one_start_or_the_check_switched_off_judges_no_ambiguity() -> None:
    lidars = [_lidar("a", is_reference=True), _lidar("b")]
    alone = judge(0.004, True, 30, 200, lidars, VerdictConfig())
    assert "unique_solution" not in {c.name for c in alone.checks}
    off = VerdictConfig(min_start_separation_sigmas=None)
    starts = StartsEvidence(3.5, 9.1, 0.8)
    unchecked = judge(0.004, True, 30, 200, lidars, off, starts=starts)
    assert unchecked.passed and "unique_solution" not in {c.name for c in unchecked.checks}


def test_two_solutions_apart_with_no_measure_of_their_difference_fail() -> None:
    lidars = [_lidar("a", is_reference=True), _lidar("b")]
    starts = StartsEvidence(0.5, 1.0, math.nan)
    verdict = judge(0.004, True, 30, 200, lidars, VerdictConfig(), starts=starts)
    assert [c.name for c in verdict.failed] == ["unique_solution"]
