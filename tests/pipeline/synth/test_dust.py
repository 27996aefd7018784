"""Dust near the sensor: a few weak returns within reach of the sensor, labelled spurious."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from pipeline.synth import make_world
from pipeline.synth.dust import DustSpec, draw_dust
from pipeline.synth.scene import NOT_STATIC
from tests.pipeline.synth.worlds import short


def test_dust_returns_stand_in_front_of_the_surface_within_their_range() -> None:
    spec = DustSpec(fraction=0.2)
    range_m = np.concatenate([np.full(5000, 0.5), np.full(5000, np.inf)])
    dust = draw_dust(spec, np.random.default_rng(0), range_m, min_range_m=0.2)
    assert 0.1 < dust.is_dust.mean() < 0.2
    assert np.all(dust.range_m[dust.is_dust] < range_m[dust.is_dust])
    assert np.all((dust.range_m[dust.is_dust] >= 0.2) & (dust.range_m[dust.is_dust] <= 1.5))
    assert np.all(np.isinf(dust.range_m[~dust.is_dust]))
    assert dust.is_dust[5000:].mean() > dust.is_dust[:5000].mean()  # a miss has no surface ahead


def test_dust_in_a_scan_is_labelled_spurious_near_the_sensor_and_weak() -> None:
    world = make_world(short("dust"), seed=4, rate_scale=0.3)
    scans = [world.simulate_scan(i, k) for i in range(2) for k in range(5)]
    spurious = np.concatenate([s.is_spurious for s in scans])
    points = np.concatenate([s.points for s in scans])
    intensity = np.concatenate([s.intensity for s in scans])
    assert 0.001 < spurious.mean() < 0.006
    assert np.linalg.norm(points[spurious], axis=1).max() <= 1.5
    assert intensity[spurious].max() <= 255 * 0.1 + 1e-3
    index = np.concatenate([s.object_index for s in scans])
    assert np.all(index[spurious] == NOT_STATIC)
    bleeding = np.concatenate([s.is_bleeding for s in scans])
    assert not (bleeding & spurious).any()


def test_a_dust_fraction_of_one_is_refused() -> None:
    with pytest.raises(ValidationError, match="less than 1"):
        DustSpec(fraction=1.0)
