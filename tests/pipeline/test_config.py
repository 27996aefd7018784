from collections.abc import Iterator
from pathlib import Path
from typing import Any, get_origin

import pytest
from pydantic import BaseModel

from pipeline.config import (
    PipelineConfig,
    config_from_mapping,
    config_hash,
    load_config,
    named_lidar_frames,
    resolved,
    unknown_frame_warnings,
)
from pipeline.errors import ConfigError

FieldPath = tuple[str, ...]
"""A field's place in the config: `("reader", "stops", "min_dwell_s")`."""


def fields(model: type[BaseModel], prefix: FieldPath = ()) -> Iterator[tuple[FieldPath, Any]]:
    """The path and type of every field of every section, nested sections (`reader.stops`)
    included, read from the models so that a new field is tested without being listed here."""
    for name, field in model.model_fields.items():
        path = (*prefix, name)
        if isinstance(field.annotation, type) and issubclass(field.annotation, BaseModel):
            yield from fields(field.annotation, path)
        else:
            yield path, field.annotation


def partial(path: FieldPath, value: Any) -> dict[str, Any]:
    """`{"denoise": {"k": 20}}` for the path `("denoise", "k")` and the value 20."""
    data: dict[str, Any] = {path[-1]: value}
    for name in reversed(path[:-1]):
        data = {name: data}
    return data


def default_at(path: FieldPath) -> Any:
    value: Any = resolved(PipelineConfig())
    for name in path:
        value = value[name]
    return value


FIELDS = dict(fields(PipelineConfig))
FIELD_PATHS = list(FIELDS)


def test_every_section_field_is_found() -> None:
    # The walk reaches the nested sections and the field PipelineConfig overrides.
    assert {("denoise", "density_ratio"), ("reader", "stops", "min_dwell_s")} <= set(FIELD_PATHS)
    assert len(FIELD_PATHS) > 60


@pytest.mark.parametrize("path", FIELD_PATHS, ids=".".join)
def test_a_section_naming_one_field_at_its_default_changes_nothing(path: FieldPath) -> None:
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


def test_settings_naming_frames_the_recording_lacks_are_warned_about() -> None:
    config = config_from_mapping(
        {
            "denoise": {
                "scan_patterns": {"lidar_top": "repetitive", "lidar_front": "repetitive"},
                "optical_axes": {"lidar_side": [0.0, 1.0, 0.0]},
            }
        }
    )
    warnings = unknown_frame_warnings(config, ("lidar_front", "lidar_rear"))
    assert len(warnings) == 2
    assert warnings[0].startswith("the config's denoise.scan_patterns names 'lidar_top', ")
    assert warnings[1].startswith("the config's denoise.optical_axes names 'lidar_side', ")
    assert all("(its LiDAR frames: lidar_front, lidar_rear)" in w for w in warnings)
    assert unknown_frame_warnings(config, ("lidar_front", "lidar_side", "lidar_top")) == ()


def test_every_setting_keyed_by_frame_is_checked() -> None:
    # Read from the models: a new per-LiDAR mapping must be added to `named_lidar_frames` (the
    # reader warns about `reader.extrinsics` itself, test_reader.py).
    mappings = {".".join(path) for path, kind in FIELDS.items() if get_origin(kind) is dict}
    assert mappings == {*named_lidar_frames(PipelineConfig()), "reader.extrinsics"} - {
        "frames.reference_frame"
    }
