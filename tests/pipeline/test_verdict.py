from pipeline.verdict import LidarEvidence, VerdictConfig, judge


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
    }
    values.update(changes)
    return LidarEvidence(**values)  # type: ignore[arg-type]


def test_a_good_calibration_passes_every_check() -> None:
    verdict = judge(
        0.004, True, 30, 200, [_lidar("a", is_reference=True), _lidar("b")], VerdictConfig()
    )
    assert verdict.passed
    names = [check.name for check in verdict.checks]
    assert names[:2] == ["metric_error", "convergence"]
    assert "determined:b" in names and "determined:a" not in names
    assert not any(name.startswith("deviation") for name in names)


def test_each_failure_is_a_named_check_with_value_and_limit() -> None:
    config = VerdictConfig(max_deviation_translation_m=0.02)
    lidars = [
        _lidar("a", is_reference=True),
        _lidar("b", undetermined=("x", "y", "yaw"), object_points=0),
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
    }
    assert failed["determined:b"].dofs == ("x", "y", "yaw")
    assert "x, y, yaw" in failed["determined:b"].detail
    assert failed["metric_error"].value == 0.05
    assert failed["metric_error"].limit == config.max_metric_error_m


def test_a_nan_value_never_passes() -> None:
    verdict = judge(float("nan"), True, 3, 200, [_lidar("a", is_reference=True)], VerdictConfig())
    assert [c.name for c in verdict.failed] == ["metric_error"]
