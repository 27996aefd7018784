from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from pydantic import BaseModel

from pipeline.config import PipelineConfig, config_from_mapping, config_hash, load_config, resolved
from pipeline.errors import ConfigError


def field_paths(model: type[BaseModel], prefix: tuple[str, ...] = ()) -> Iterator[tuple[str, ...]]:
    """The path of every field of every section, nested sections (`reader.stops`) included,
    read from the models so that a new field is tested without being listed here."""
    for name, field in model.model_fields.items():
        path = (*prefix, name)
        if isinstance(field.annotation, type) and issubclass(field.annotation, BaseModel):
            yield from field_paths(field.annotation, path)
        else:
            yield path


def partial(path: tuple[str, ...], value: Any) -> dict[str, Any]:
    """`{"denoise": {"k": 20}}` for the path `("denoise", "k")` and the value 20."""
    data: dict[str, Any] = {path[-1]: value}
    for name in reversed(path[:-1]):
        data = {name: data}
    return data


def default_at(path: tuple[str, ...]) -> Any:
    value: Any = resolved(PipelineConfig())
    for name in path:
        value = value[name]
    return value


FIELD_PATHS = list(field_paths(PipelineConfig))


def test_every_section_field_is_found() -> None:
    # The walk reaches the nested sections and the field PipelineConfig overrides.
    assert {("denoise", "density_ratio"), ("reader", "stops", "min_dwell_s")} <= set(FIELD_PATHS)
    assert len(FIELD_PATHS) > 60


@pytest.mark.parametrize("path", FIELD_PATHS, ids=".".join)
def test_a_section_naming_one_field_at_its_default_changes_nothing(path: tuple[str, ...]) -> None:
    config = config_from_mapping(partial(path, default_at(path)))
    assert resolved(config) == resolved(PipelineConfig())
    assert config_hash(config) == config_hash(PipelineConfig())


def test_a_partial_denoise_section_keeps_the_pipelines_density_ratio(tmp_path: Path) -> None:
    path = tmp_path / "config.yaml"
    path.write_text("denoise:\n  k: 24\n")
    config = load_config(path)
    assert config.denoise.k == 24
    assert config.denoise.density_ratio == PipelineConfig().denoise.density_ratio == 2.5


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
