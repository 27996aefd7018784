"""Random rigid perturbations with bounded size: how initial extrinsics and odometry go wrong."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field
from scipy.spatial.transform import Rotation

from pipeline.transforms import Matrix4, make_transform


class PerturbationBounds(BaseModel):
    """Largest translation (norm, metres) and rotation (angle, degrees) of one perturbation."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    translation_m: float = Field(ge=0)
    rotation_deg: float = Field(ge=0, le=180)


def random_perturbation(rng: np.random.Generator, bounds: PerturbationBounds) -> Matrix4:
    """A transform `delta` with `|t| <= translation_m` and rotation angle `<= rotation_deg`.

    The translation is uniform in the ball of that radius; the rotation has a uniform random axis
    and an angle uniform in `[0, rotation_deg]`. Applied on the right (`T @ delta`), it moves a
    pose by exactly `|t|` and turns it by exactly the angle, so `pose_difference` stays in bounds.
    """
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    translation = direction * bounds.translation_m * rng.random() ** (1.0 / 3.0)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = math.radians(bounds.rotation_deg) * rng.random()
    return make_transform(Rotation.from_rotvec(axis * angle).as_matrix(), translation)


class PlanarDrift(BaseModel):
    """Odometry drift that grows with the wheel travel: at the route's end the base-frame error
    is exactly `translation_m` in the floor plane and `rotation_deg` about z (the direction and
    the sense are drawn per seed); at a stop it is that share of both, as travelled so far."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    translation_m: float = Field(default=0.0, ge=0)
    rotation_deg: float = Field(default=0.0, ge=0, le=180)


def drift_errors(
    rng: np.random.Generator, drift: PlanarDrift, fractions: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(K, 4, 4) planar errors at the travelled `fractions` (K,) in [0, 1] of the route."""
    heading = rng.uniform(-math.pi, math.pi)
    sense = 1.0 if rng.random() < 0.5 else -1.0
    out = np.zeros((len(fractions), 4, 4))
    angle = sense * math.radians(drift.rotation_deg) * fractions
    out[:, :3, :3] = Rotation.from_euler("z", angle[:, None]).as_matrix()
    out[:, 0, 3] = drift.translation_m * fractions * math.cos(heading)
    out[:, 1, 3] = drift.translation_m * fractions * math.sin(heading)
    out[:, 3, 3] = 1.0
    return out
