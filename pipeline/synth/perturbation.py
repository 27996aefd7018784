"""Random rigid perturbations with bounded size: how initial extrinsics and odometry go wrong."""

from __future__ import annotations

import math

import numpy as np
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
