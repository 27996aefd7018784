"""Bleeding models: how a LiDAR's beam mixes returns at depth edges, as a randomised axis.

The synthesiser's own footprint (`raycast.cast_with_footprint`: six sub-rays on a ring of the
LiDAR model's `footprint_deg`, a Beta-drawn blend) is one beam among many; a stage 1 tuned on it
alone did not travel to other simulators' clouds (issue 19). A `BleedingModel` is another beam,
used when a world is made with one (`make_world(..., bleeding=model)`); scenarios made without one
render exactly as before. `draw_bleeding_case(seed)` draws a model, a scan pattern, a scene and a
scene seed from the table `BLEEDING_RANGES`:

| factor | range |
|---|---|
| scan pattern (alternating with the seed) | rosette (Mid-70), spinning (16 beams) |
| scene | rosette: set1-box, -cylinder, -capsule; spinning: `spinning` |
| scene seed | 100-9999 |
| beam divergence, major axis (full angle) | 0.03-1.2 deg, log-uniform |
| beam divergence, minor / major | 0.1-1 (the minor axis never below 0.03 deg) |
| ellipse orientation: major axis from the sensor's horizontal | 0-180 deg |
| sub-rays per beam (uniform inside the ellipse, fresh for every beam) | 4-16 |
| probability of a mixed return where the sub-rays hit two surfaces | 0.2-1.0 |
| two surfaces: distinct geoms farther apart along the beam than | 0.1 m (fixed) |
| where a mixed return's range falls between the nearest and farthest hit | uniform, energy |

`uniform`: anywhere between the two, evenly. `energy`: the mean of the sub-rays' ranges weighted
by the energy each returns (reflectivity x cos(incidence) / range^2), as a receiver that
integrates one pulse reports it. A beam that hits two surfaces but gives no mixed return reports
its strongest surface (the energy-weighted range of the sub-rays on the side, near or far, that
returns more energy). Points are labelled bleeding as with the default footprint: they lie
farther than three range-noise sigmas from every surface.

Each draw comes from its own random stream (`[seed, stream]`), so adding a factor to one stream
leaves the others' draws alone; `pipeline.synth.random_scenario` does not draw a bleeding model,
so random scenarios render as before.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

RangeRule = Literal["uniform", "energy"]
ScanPatternKind = Literal["rosette", "spinning"]
Range = tuple[float, float]

_FROZEN = ConfigDict(frozen=True, extra="forbid")
# Stream ids of `draw_bleeding_case`: one per concern.
_BEAM, _SCENE = 1, 2


class BleedingModel(BaseModel):
    """One beam model: an elliptical footprint sampled by sub-rays, and what a receiver reports
    where they straddle an edge. Angles are full angles in degrees."""

    model_config = _FROZEN

    divergence_deg: tuple[float, float] = Field(
        description="full angles of the beam's ellipse, (major, minor); e.g. Mid-70: (0.28, 0.03)"
    )
    ellipse_angle_deg: float = Field(
        default=0.0,
        description="the major axis's angle from the sensor's horizontal, about the beam",
    )
    sub_rays: int = Field(default=8, ge=2, description="sub-rays per beam inside the ellipse")
    mixed_probability: float = Field(
        default=0.5, ge=0.0, le=1.0, description="a beam over two surfaces gives a mixed return"
    )
    range_rule: RangeRule = "uniform"
    min_gap_m: float = Field(
        default=0.1, gt=0.0, description="two surfaces closer than this along the beam are one"
    )

    @model_validator(mode="after")
    def _check(self) -> BleedingModel:
        major, minor = self.divergence_deg
        if not 0.0 < minor <= major < 90.0:
            raise ValueError(
                f"divergence_deg {self.divergence_deg} must be (major, minor) with "
                "0 < minor <= major < 90 degrees"
            )
        return self

    @property
    def half_angles_rad(self) -> tuple[float, float]:
        """Semi-axes of the footprint ellipse (major, minor), radians."""
        major, minor = self.divergence_deg
        return math.radians(major) / 2.0, math.radians(minor) / 2.0


class BleedingRanges(BaseModel):
    """The table of the module docstring."""

    model_config = _FROZEN

    patterns: tuple[ScanPatternKind, ...] = ("rosette", "spinning")
    rosette_scenes: tuple[str, ...] = ("set1-box", "set1-cylinder", "set1-capsule")
    spinning_scene: str = "spinning"
    divergence_major_deg: Range = (0.03, 1.2)
    minor_over_major: Range = (0.1, 1.0)
    divergence_minor_min_deg: float = 0.03
    ellipse_angle_deg: Range = (0.0, 180.0)
    sub_rays: tuple[int, int] = (4, 16)
    mixed_probability: Range = (0.2, 1.0)
    range_rules: tuple[RangeRule, ...] = ("uniform", "energy")
    scene_seeds: tuple[int, int] = (100, 10_000)
    """Scene seeds apart from those the default filter was tuned on (0, 1) and the benchmarks'."""


BLEEDING_RANGES = BleedingRanges()


class BleedingCase(BaseModel):
    """One draw: a beam model on a scene seen by LiDARs with one scan pattern."""

    model_config = _FROZEN

    pattern: ScanPatternKind
    scenario: str
    scene_seed: int
    bleeding: BleedingModel

    def describe(self) -> str:
        """A short line for the benchmark's tables."""
        model = self.bleeding
        major, minor = model.divergence_deg
        return (
            f"{self.scenario}:{self.scene_seed} {major:.2f}x{minor:.2f} deg "
            f"@{model.ellipse_angle_deg:.0f}, {model.sub_rays} rays, "
            f"p {model.mixed_probability:.2f}, {model.range_rule}"
        )


def draw_bleeding(
    rng: np.random.Generator, ranges: BleedingRanges = BLEEDING_RANGES
) -> BleedingModel:
    """A beam model from `ranges`: divergence log-uniform (a decade and a half of beams is as
    likely at its narrow end as at its wide one)."""
    low, high = ranges.divergence_major_deg
    major = float(math.exp(rng.uniform(math.log(low), math.log(high))))
    minor = max(
        float(rng.uniform(*ranges.minor_over_major)) * major, ranges.divergence_minor_min_deg
    )
    return BleedingModel(
        divergence_deg=(major, min(minor, major)),
        ellipse_angle_deg=float(rng.uniform(*ranges.ellipse_angle_deg)),
        sub_rays=int(rng.integers(ranges.sub_rays[0], ranges.sub_rays[1] + 1)),
        mixed_probability=float(rng.uniform(*ranges.mixed_probability)),
        range_rule=ranges.range_rules[int(rng.integers(len(ranges.range_rules)))],
    )


def draw_bleeding_case(seed: int, ranges: BleedingRanges = BLEEDING_RANGES) -> BleedingCase:
    """Draw `seed`'s case: the pattern (by the seed's parity), the beam and the scene (each
    from its own random stream)."""
    pattern = ranges.patterns[seed % len(ranges.patterns)]
    scene_rng = np.random.default_rng([seed, _SCENE])
    scenario = (
        ranges.rosette_scenes[int(scene_rng.integers(len(ranges.rosette_scenes)))]
        if pattern == "rosette"
        else ranges.spinning_scene
    )
    return BleedingCase(
        pattern=pattern,
        scenario=scenario,
        scene_seed=int(scene_rng.integers(*ranges.scene_seeds)),
        bleeding=draw_bleeding(np.random.default_rng([seed, _BEAM]), ranges),
    )
