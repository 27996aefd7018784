from pathlib import Path

import pytest

from pipeline.config import PipelineConfig, config_hash, load_config, resolved
from pipeline.errors import ConfigError


def test_a_yaml_file_overrides_only_what_it_names(tmp_path: Path) -> None:
    path = tmp_path / "config.yaml"
    path.write_text(
        "optimisation:\n  residual: point_to_point\nverdict:\n  max_metric_error_m: 0.03\n"
    )
    config = load_config(path)
    assert config.optimisation.residual == "point_to_point"
    assert config.verdict.max_metric_error_m == 0.03
    assert config.segmentation == PipelineConfig().segmentation


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("optimisation:\n  residuals: point_to_point\n", "optimisation.residuals"),
        ("segmentation:\n  floor_distance_m: -1\n", "segmentation.floor_distance_m"),
        ("- 1\n- 2\n", "must hold a mapping"),
        ("a: [\n", "not valid YAML"),
    ],
)
def test_unknown_keys_and_bad_values_are_config_errors(
    tmp_path: Path, text: str, match: str
) -> None:
    path = tmp_path / "config.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match):
        load_config(path)


def test_a_missing_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read config file"):
        load_config(tmp_path / "absent.yaml")


def test_the_hash_names_the_resolved_config() -> None:
    default = PipelineConfig()
    changed = PipelineConfig.model_validate({"segmentation": {"min_cluster_points": 31}})
    assert config_hash(default).startswith("sha256:") and len(config_hash(default)) == 71
    assert config_hash(default) == config_hash(PipelineConfig.model_validate(resolved(default)))
    assert config_hash(default) != config_hash(changed)
