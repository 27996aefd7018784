"""The smooth-surface test: a plane seen at grazing incidence is smooth, a step is not."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.denoise.slope import on_smooth_surface

TAU = 0.08


def _neighbourhood(
    ranges_of: object, seed: int = 0
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """One point straight ahead (+x) and 16 neighbouring directions within 0.3 deg, their range
    differences from `ranges_of(directions)` (the point's range is that of +x)."""
    rng = np.random.default_rng(seed)
    offsets = np.radians(0.3) * rng.uniform(-1.0, 1.0, (16, 2))
    neighbours = np.column_stack([np.ones(16), offsets])
    neighbours /= np.linalg.norm(neighbours, axis=1, keepdims=True)
    unit = np.array([[1.0, 0.0, 0.0]])
    ranges = ranges_of(neighbours)  # type: ignore[operator]
    own = ranges_of(unit)[0]  # type: ignore[operator]
    return unit, neighbours[None], (ranges - own)[None]


def _plane(normal: NDArray[np.float64], distance: float) -> object:
    return lambda units: distance / (units @ normal)


def test_a_plane_at_grazing_incidence_is_smooth() -> None:
    # 86 deg from facing the beam: the range climbs 0.4 m across the neighbourhood, and only
    # 7 of the 16 neighbours lie within tau of the point.
    tilt = np.radians(86.0)
    normal = np.array([np.cos(tilt), np.sin(tilt), 0.0])
    unit, neighbours, diff = _neighbourhood(_plane(normal, 0.2))
    assert np.ptp(diff) > 4 * TAU
    assert on_smooth_surface(unit, neighbours, diff, TAU).all()


def test_a_return_between_two_surfaces_is_not() -> None:
    # The point at 2.0 m; its neighbours on a near surface (1.5 m) on one side, a far one
    # (2.5 m) on the other.
    def step(units: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.where(units[:, 1] < 0.0, 1.5, np.where(units[:, 1] > 0.0, 2.5, 2.0))

    unit, neighbours, diff = _neighbourhood(step)
    assert not on_smooth_surface(unit, neighbours, diff, TAU).any()


def test_no_points_no_answer() -> None:
    empty = np.zeros((0, 3))
    assert on_smooth_surface(empty, np.zeros((0, 16, 3)), np.zeros((0, 16)), TAU).shape == (0,)
