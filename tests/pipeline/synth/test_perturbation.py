"""Perturbations stay within their bounds and use most of them."""

from __future__ import annotations

import numpy as np

from pipeline.synth.perturbation import PerturbationBounds, random_perturbation
from pipeline.transforms import pose_difference


def test_perturbations_stay_within_bounds_and_reach_near_them() -> None:
    rng = np.random.default_rng(3)
    bounds = PerturbationBounds(translation_m=0.2, rotation_deg=5.0)
    T = np.eye(4)
    T[:3, 3] = [1.0, 2.0, 0.5]
    sizes = np.array([pose_difference(T, T @ random_perturbation(rng, bounds)) for _ in range(500)])
    assert sizes[:, 0].max() <= 0.2 + 1e-12 and sizes[:, 1].max() <= 5.0 + 1e-9
    assert sizes[:, 0].max() > 0.18 and sizes[:, 1].max() > 4.8
