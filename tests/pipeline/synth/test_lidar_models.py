"""Scan models: directions inside the field of view, rosette coverage growing with time, masks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.problem import ScanPattern
from pipeline.synth.lidar_models import BeamField, Mid70, Mid360, SpinningLidar


def _coverage(directions: np.ndarray, cell_deg: float = 0.5) -> float:
    """Share of the Mid-70's circular field (in cells of the angle plane) that some ray hit."""
    off_axis = np.arccos(np.clip(directions[:, 0], -1, 1))
    azimuth = np.arctan2(directions[:, 2], directions[:, 1])
    y, z = np.degrees(off_axis) * np.cos(azimuth), np.degrees(off_axis) * np.sin(azimuth)
    cells = {
        (int(a), int(b))
        for a, b in zip(np.floor(y / cell_deg), np.floor(z / cell_deg), strict=True)
    }
    return len(cells) / (math.pi * 35.2**2 / cell_deg**2)


def test_mid70_rays_are_unit_vectors_inside_the_cone() -> None:
    firing = Mid70().firing(0.0, 0.2)
    assert len(firing) == 20_000
    np.testing.assert_allclose(np.linalg.norm(firing.directions, axis=1), 1.0, atol=1e-12)
    off_axis = np.degrees(np.arccos(np.clip(firing.directions @ Mid70().optical_axis, -1, 1)))
    assert off_axis.max() <= 35.2 + 1e-9
    assert off_axis.max() > 34.0, "the rosette should reach the edge of the field of view"
    assert np.all(np.diff(firing.times) > 0)


def test_mid70_coverage_grows_with_integration_time() -> None:
    model = Mid70()
    coverage = [_coverage(model.firing(0.0, seconds).directions) for seconds in (0.1, 0.3, 1.0)]
    assert coverage[0] < coverage[1] < coverage[2]
    assert coverage[2] > 2.5 * coverage[0], coverage
    assert coverage[2] > 0.6, coverage


def test_mid70_pattern_does_not_repeat_from_scan_to_scan() -> None:
    model = Mid70()
    first, second = model.firing(0.0, 0.1), model.firing(0.1, 0.1)
    assert not np.allclose(first.directions[:100], second.directions[:100], atol=1e-3)


def test_consecutive_spans_tile_the_firing_grid() -> None:
    model = Mid70()
    whole = model.firing(0.2, 0.3, rate_scale=0.37)
    parts = [model.firing(0.2 + 0.1 * k, 0.1, rate_scale=0.37) for k in range(3)]
    np.testing.assert_array_equal(np.concatenate([p.times for p in parts]), whole.times)
    np.testing.assert_array_equal(np.concatenate([p.directions for p in parts]), whole.directions)


def test_rate_scale_thins_the_points() -> None:
    model = Mid70()
    assert len(model.firing(0.0, 0.1, rate_scale=0.1)) == 1000


def test_spinning_lidar_keeps_only_the_azimuth_mask() -> None:
    model = SpinningLidar(azimuth_mask_deg=(-70.0, 70.0))
    firing = model.firing(0.0, model.scan_period_s)
    azimuth = np.degrees(np.arctan2(firing.directions[:, 1], firing.directions[:, 0]))
    elevation = np.degrees(np.arcsin(firing.directions[:, 2]))
    assert azimuth.min() >= -70.0 - 1e-9 and azimuth.max() <= 70.0 + 1e-9
    assert elevation.min() == pytest.approx(-15.0) and elevation.max() == pytest.approx(15.0)
    assert len(firing) == pytest.approx(model.rate() * model.scan_period_s, rel=0.01)
    np.testing.assert_allclose(model.optical_axis, [1.0, 0.0, 0.0], atol=1e-12)


def test_spinning_lidar_publishes_each_points_beam_as_ring() -> None:
    model = SpinningLidar(azimuth_mask_deg=(-70.0, 70.0))
    firing = model.firing(0.0, model.scan_period_s)
    ranges = np.random.default_rng(0).uniform(0.5, 20.0, len(firing))
    ring = model.point_fields(firing.directions * ranges[:, None])["ring"]
    assert ring.dtype == np.uint16
    # Beams of one column fire together, lowest elevation first.
    np.testing.assert_array_equal(ring, np.tile(np.arange(model.beams), len(firing) // model.beams))
    assert model.scan_pattern is ScanPattern.REPETITIVE
    assert Mid70().scan_pattern is ScanPattern.NON_REPETITIVE
    assert Mid70().point_fields(firing.directions) == {}


def test_spinning_mask_must_be_ordered() -> None:
    with pytest.raises(ValueError, match="yaw the mount"):
        SpinningLidar(azimuth_mask_deg=(90.0, -90.0))


@pytest.mark.parametrize("name", ["ring", "channel", "laser_id"])
def test_spinning_lidar_names_its_beam_field_as_its_driver_does(name: BeamField) -> None:
    model = SpinningLidar(beams=32, elevation_deg=(-25.0, 15.0), beam_field=name)
    firing = model.firing(0.0, 0.01)
    fields = model.point_fields(firing.directions * 5.0)
    assert list(fields) == [name]
    np.testing.assert_array_equal(fields[name], np.tile(np.arange(32), len(firing) // 32))


def test_spinning_lidar_without_a_beam_field_publishes_none() -> None:
    model = SpinningLidar(beam_field=None)
    assert model.point_fields(model.firing(0.0, 0.01).directions) == {}
    assert model.scan_pattern is ScanPattern.REPETITIVE


def _band_coverage(directions: np.ndarray, cell_deg: float = 1.0) -> float:
    azimuth = np.degrees(np.arctan2(directions[:, 1], directions[:, 0]))
    elevation = np.degrees(np.arcsin(np.clip(directions[:, 2], -1, 1)))
    cells = {
        (int(a), int(b))
        for a, b in zip(np.floor(azimuth / cell_deg), np.floor(elevation / cell_deg), strict=True)
    }
    return len(cells) / (360.0 * 59.0 / cell_deg**2)


def test_mid360_covers_its_band_all_round_and_keeps_filling_in() -> None:
    model = Mid360()
    firing = model.firing(0.0, 0.1)
    assert len(firing) == 20_000
    np.testing.assert_allclose(np.linalg.norm(firing.directions, axis=1), 1.0, atol=1e-12)
    elevation = np.degrees(np.arcsin(firing.directions[:, 2]))
    assert elevation.min() >= -7.0 - 1e-9 and elevation.max() <= 52.0 + 1e-9
    azimuth = np.degrees(np.arctan2(firing.directions[:, 1], firing.directions[:, 0]))
    assert np.histogram(azimuth, bins=36, range=(-180, 180))[0].min() > 0
    coverage = [_band_coverage(model.firing(0.0, s).directions) for s in (0.1, 0.3, 1.0)]
    assert coverage[0] < coverage[1] < coverage[2] and coverage[2] > 1.5 * coverage[0], coverage
    assert model.scan_pattern is ScanPattern.NON_REPETITIVE


def test_mid360_pattern_continues_across_scans_and_names_each_points_line() -> None:
    model = Mid360()
    whole = model.firing(0.0, 0.2, rate_scale=0.1)
    parts = [model.firing(0.0, 0.1, rate_scale=0.1), model.firing(0.1, 0.1, rate_scale=0.1)]
    np.testing.assert_array_equal(np.concatenate([p.directions for p in parts]), whole.directions)
    line = model.point_fields(whole.directions * 3.0)["line"]
    assert line.dtype == np.uint8
    np.testing.assert_array_equal(line, np.arange(len(whole)) % 4)
    assert Mid360(line_field=False).point_fields(whole.directions) == {}
