"""Spurious returns near the sensor: dust in the air answering a few pulses before any surface.

A dust return replaces the ray's true return (or its miss) by a weak one at a random short range,
as airborne particles do; each is labelled spurious, never part of the world's geometry.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field


class DustSpec(BaseModel):
    """A share `fraction` of a LiDAR's rays returns from dust within `range_m` of the sensor."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    fraction: float = Field(default=0.003, gt=0, lt=1)
    range_m: tuple[float, float] = (0.1, 1.5)
    reflectivity: tuple[float, float] = (0.02, 0.1)


@dataclass(frozen=True)
class DustReturns:
    """Per ray: `is_dust` (N,) bool, and where it is set the dust's `range_m` (N,) and
    `reflectivity` (N,) (inf and 0 elsewhere)."""

    is_dust: NDArray[np.bool_]
    range_m: NDArray[np.float64]
    reflectivity: NDArray[np.float64]


def draw_dust(
    spec: DustSpec, rng: np.random.Generator, range_m: NDArray[np.float64], min_range_m: float
) -> DustReturns:
    """Dust for rays whose true returns are `range_m` (N,) (inf: a miss). Dust stands in front of
    the surface; a draw behind it, or nearer than the LiDAR's `min_range_m`, is no return."""
    n = len(range_m)
    fires = rng.random(n) < spec.fraction
    distance = rng.uniform(*spec.range_m, size=n)
    reflectivity = rng.uniform(*spec.reflectivity, size=n)
    is_dust = fires & (distance < range_m) & (distance >= min_range_m)
    return DustReturns(
        is_dust=is_dust,
        range_m=np.where(is_dust, distance, np.inf),
        reflectivity=np.where(is_dust, reflectivity, 0.0),
    )
