"""bench_minimum: variants and noise settings parse, and stage 4 runs from both starts."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.synth.random_scenario import random_scenario
from tests.bench.bench_minimum import (
    HEADER,
    parse_noise,
    parse_variant,
    recording,
    row,
    run_case,
    with_noise,
)


def test_variants_parse_their_values_as_json_or_words() -> None:
    variant = parse_variant(
        "raw:segmentation.smooth_objects=false, segmentation.voxel_size_m=0.04,"
        "segmentation.surface_model=beam_quadric"
    )
    assert variant.name == "raw"
    assert variant.overrides == {
        "segmentation.smooth_objects": False,
        "segmentation.voxel_size_m": 0.04,
        "segmentation.surface_model": "beam_quadric",
    }
    config = variant.config()
    assert not config.segmentation.smooth_objects
    assert config.segmentation.voxel_size_m == 0.04
    assert parse_variant("default").overrides == {}


def test_a_bad_variant_says_how_to_write_it() -> None:
    with pytest.raises(SystemExit, match=r"section\.key=value"):
        parse_variant("x:segmentation.voxel_size_m")
    with pytest.raises(SystemExit, match=r"not a section\.key"):
        parse_variant("x:nosuchsection.key=1").config()


def test_noise_scales_each_lidar_or_every_one() -> None:
    spec = random_scenario(1060)
    noises = [mount.model.range_noise_m for mount in spec.lidars]
    assert [m.model.range_noise_m for m in with_noise(spec, (1.0, 0.0)).lidars] == [noises[0], 0.0]
    assert [m.model.range_noise_m for m in with_noise(spec, (2.0,)).lidars] == [
        2 * n for n in noises
    ]
    with pytest.raises(SystemExit, match="one per LiDAR"):
        with_noise(spec, (1.0, 1.0, 1.0))
    assert parse_noise("1,0") == (1.0, 0.0)
    for bad in ("a", "-1"):
        with pytest.raises(SystemExit, match="--noise"):
            parse_noise(bad)


def test_stage_4_from_the_truth_ends_near_it_on_a_noise_free_recording(tmp_path: Path) -> None:
    directory = recording(tmp_path, 0.1, 1060, (0.0,))
    start, truth = run_case(directory, parse_variant("default"))
    # Noise-free, the minimum of the cost is the truth: started there, stage 4 stays.
    assert truth.translation_mm < 2.0 and truth.rotation_deg < 0.05
    assert start.iterations > 0 and truth.iterations > 0
    line = row(1060, "rotate/mixed/large", "0", "default", start, truth)
    assert line.count("|") == HEADER.splitlines()[0].count("|")
