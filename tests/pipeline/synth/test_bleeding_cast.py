"""Rendering with a bleeding model: mixed returns appear only where asked, labelled and placed
between the surfaces they mix; the default footprint is untouched (see test_existing_renders)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.synth import make_world
from pipeline.synth.bleeding import BleedingModel
from pipeline.synth.bleeding_cast import sub_rays

WIDE = BleedingModel(divergence_deg=(1.0, 0.5), sub_rays=8, mixed_probability=1.0)


def _stop_labels(model: BleedingModel | None, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    world = make_world("tiny", seed, bleeding=model)
    scans = world.simulate_stop(0, 0)
    return (
        np.concatenate([s.points for s in scans]),
        np.concatenate([s.is_bleeding for s in scans]),
    )


def test_sub_rays_lie_inside_the_ellipse() -> None:
    rng = np.random.default_rng(0)
    model = BleedingModel(divergence_deg=(1.0, 0.1), sub_rays=500, ellipse_angle_deg=0.0)
    beam = np.array([[1.0, 0.0, 0.0]])
    rays = sub_rays(beam, np.array([[0.0, 0.0, 1.0]]), model, rng)[0]
    # Horizontal (y) offsets reach the major semi-axis, vertical (z) only the minor one.
    y, z = np.degrees(np.arctan2(rays[:, 1], rays[:, 0])), np.degrees(rays[:, 2])
    assert np.all((y / 0.5) ** 2 + (z / 0.05) ** 2 <= 1.0 + 1e-6)
    assert y.max() > 0.45 and np.abs(z).max() < 0.051


@pytest.mark.parametrize("rule", ["uniform", "energy"])
def test_a_wide_beam_bleeds_and_a_certain_mix_bleeds_more(rule: str) -> None:
    points, bleeding = _stop_labels(WIDE.model_copy(update={"range_rule": rule}))
    _, fewer = _stop_labels(WIDE.model_copy(update={"range_rule": rule, "mixed_probability": 0.2}))
    assert bleeding.sum() > 10
    assert fewer.sum() < bleeding.sum()
    assert len(points) == len(bleeding)


def test_no_mixing_leaves_no_bleeding_points() -> None:
    _, bleeding = _stop_labels(WIDE.model_copy(update={"mixed_probability": 0.0}))
    _, default = _stop_labels(None)
    assert default.sum() > 0  # the default footprint of the tiny scenario bleeds
    # Strongest returns only: a few can float off a surface (reported along the beam's centre,
    # at a sub-ray's range), far fewer than with mixing.
    assert bleeding.sum() < 0.2 * _stop_labels(WIDE)[1].sum()


def test_the_same_world_renders_the_same_scan() -> None:
    a, la = _stop_labels(WIDE)
    b, lb = _stop_labels(WIDE)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(la, lb)
