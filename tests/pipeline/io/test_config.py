"""Reader config validation: bad values say which setting is wrong."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from pipeline.io.config import PoseConfig, ReaderConfig, StopDetectionConfig


def test_defaults_follow_the_input_contract() -> None:
    config = ReaderConfig()
    assert (config.odometry_topic, config.odom_frame, config.base_frame) == (
        "/odom",
        "odom",
        "base_link",
    )
    assert config.trajectory == "auto" and config.lidar_topics == ()


def test_pose_matrix() -> None:
    T = PoseConfig(translation=(1.0, 2.0, 3.0), rotation_xyzw=(0.0, 0.0, 1.0, 0.0)).matrix()
    np.testing.assert_allclose(
        T, [[-1, 0, 0, 1], [0, -1, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]], atol=1e-12
    )


def test_zero_quaternion_is_refused() -> None:
    with pytest.raises(ValidationError, match=r"non-zero quaternion"):
        PoseConfig(translation=(0.0, 0.0, 0.0), rotation_xyzw=(0.0, 0.0, 0.0, 0.0))


@pytest.mark.parametrize("bad", [{"min_dwell_s": 0}, {"max_linear_speed": -1.0}, {"typo": 1}])
def test_bad_stop_settings(bad: dict[str, float]) -> None:
    with pytest.raises(ValidationError, match=next(iter(bad))):
        StopDetectionConfig(**bad)


def test_configs_are_frozen() -> None:
    with pytest.raises(ValidationError, match=r"frozen"):
        ReaderConfig().base_frame = "x"
