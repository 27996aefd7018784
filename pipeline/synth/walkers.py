"""People and carts walking through the scene while the robot records.

Each walker paces a straight stretch of floor back and forth at a constant speed, turning round
at its ends, so it stands somewhere else in every scan and walks in and out of the LiDARs' views
within a stop. Walkers keep clear of the robot's path; low objects are placed clear of theirs.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from pipeline.errors import ConfigError
from pipeline.synth.objects import ObjectKind, ObjectRole, SceneObject
from pipeline.synth.room import Room
from pipeline.transforms import from_xyz_rpy

_TRIES = 200
_PATH_SAMPLES = 64


class WalkerKind(enum.StrEnum):
    PERSON = "person"
    CART = "cart"


class WalkersSpec(BaseModel):
    """What the seed draws walkers from (every range uniform)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    count: tuple[int, int] = (1, 2)
    kinds: tuple[WalkerKind, ...] = (WalkerKind.PERSON,)
    speed_mps: tuple[float, float] = (0.5, 1.5)
    offset_m: tuple[float, float] = Field(
        default=(1.0, 3.5), description="distance of a walker's line from the origin"
    )
    path_length_m: tuple[float, float] = (3.0, 6.0)
    person_radius_m: tuple[float, float] = (0.18, 0.25)
    person_height_m: tuple[float, float] = (1.6, 1.9)
    cart_size_m: tuple[tuple[float, float], tuple[float, float], tuple[float, float]] = (
        (0.8, 1.2),
        (0.5, 0.7),
        (0.9, 1.1),
    )
    reflectivity: tuple[float, float] = (0.1, 0.9)


@dataclass(frozen=True)
class Walker:
    """A person (upright cylinder: `radius`, `height`) or a cart (box `x` along its way, `y`,
    `z`) pacing from `start` (2,) to `end` (2,) and back at `speed_mps`; at time 0 it is
    `phase` (in [0, 1)) of the way round one lap (there and back)."""

    kind: WalkerKind
    dimensions: Mapping[str, float]
    start: NDArray[np.float64]
    end: NDArray[np.float64]
    speed_mps: float
    phase: float
    reflectivity: float

    @property
    def length_m(self) -> float:
        return float(np.linalg.norm(self.end - self.start))

    @property
    def radius_xy(self) -> float:
        d = self.dimensions
        if self.kind is WalkerKind.PERSON:
            return d["radius"]
        return 0.5 * math.hypot(d["x"], d["y"])

    @property
    def height_m(self) -> float:
        return self.dimensions["height" if self.kind is WalkerKind.PERSON else "z"]

    def positions(self, t: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Where the walker stands at times `t` (K,) (seconds since the recording started):
        xy (K, 2) and heading (K,) rad."""
        lap = np.mod(self.phase + np.asarray(t) * self.speed_mps / (2.0 * self.length_m), 1.0)
        share = 1.0 - np.abs(2.0 * lap - 1.0)  # 0 at start, 1 at end, back to 0
        way = self.end - self.start
        xy = self.start + share[:, None] * way
        heading = math.atan2(way[1], way[0]) + np.where(lap < 0.5, 0.0, math.pi)
        return xy, heading

    def at(self, t: float, ground_m: float = 0.0) -> SceneObject:
        """The walker as an object at time `t`, its feet at height `ground_m`."""
        xy, heading = self.positions(np.array([t]))
        kind = ObjectKind.CYLINDER if self.kind is WalkerKind.PERSON else ObjectKind.BOX
        T = from_xyz_rpy(
            [xy[0, 0], xy[0, 1], ground_m + 0.5 * self.height_m], [0.0, 0.0, heading[0]]
        )
        return SceneObject(kind, self.dimensions, T, self.reflectivity, ObjectRole.WALKER)

    def path_gap(self, xy: NDArray[np.float64], radius: float) -> float:
        """Free space between a circle (`xy` (2,), `radius`) and the floor this walker sweeps."""
        way = self.end - self.start
        s = float(np.clip((xy - self.start) @ way / (way @ way), 0.0, 1.0))
        return float(np.linalg.norm(xy - self.start - s * way)) - self.radius_xy - radius

    def to_json(self) -> dict[str, Any]:
        return {
            "kind": self.kind.value,
            "dimensions": dict(self.dimensions),
            "start": self.start.tolist(),
            "end": self.end.tolist(),
            "speed_mps": self.speed_mps,
            "phase": self.phase,
            "reflectivity": self.reflectivity,
            "motion": "paces start -> end -> start at speed_mps; at t = 0 (the recording's "
            "start) it is phase of the way round one lap",
        }

    @staticmethod
    def from_json(doc: Mapping[str, Any]) -> Walker:
        return Walker(
            kind=WalkerKind(doc["kind"]),
            dimensions=dict(doc["dimensions"]),
            start=np.asarray(doc["start"], dtype=np.float64),
            end=np.asarray(doc["end"], dtype=np.float64),
            speed_mps=float(doc["speed_mps"]),
            phase=float(doc["phase"]),
            reflectivity=float(doc["reflectivity"]),
        )


def draw_walkers(
    spec: WalkersSpec,
    rng: np.random.Generator,
    band: tuple[float, float],
    room: Room | None = None,
) -> tuple[Walker, ...]:
    """Draw the walkers. `band`: inner and outer radius of the ring the robot's footprint
    sweeps (with its clearance); walkers never enter it. In a room they stay on its free floor."""
    count = int(rng.integers(spec.count[0], spec.count[1] + 1))
    return tuple(_draw_one(spec, rng, band, room) for _ in range(count))


def _draw_one(
    spec: WalkersSpec, rng: np.random.Generator, band: tuple[float, float], room: Room | None
) -> Walker:
    kind = spec.kinds[int(rng.integers(len(spec.kinds)))]
    dimensions: dict[str, float]
    if kind is WalkerKind.PERSON:
        dimensions = {
            "radius": float(rng.uniform(*spec.person_radius_m)),
            "height": float(rng.uniform(*spec.person_height_m)),
        }
    else:
        x, y, z = (float(rng.uniform(*r)) for r in spec.cart_size_m)
        dimensions = {"x": x, "y": y, "z": z}
    speed = float(rng.uniform(*spec.speed_mps))
    phase = float(rng.random())
    reflectivity = float(rng.uniform(*spec.reflectivity))
    radius = Walker(kind, dimensions, np.zeros(2), np.ones(2), 1.0, 0.0, 0.0).radius_xy
    for _ in range(_TRIES):
        angle = rng.uniform(-math.pi, math.pi)
        along = np.array([math.cos(angle), math.sin(angle)])
        foot = rng.uniform(*spec.offset_m) * np.array([-along[1], along[0]])
        length = float(rng.uniform(*spec.path_length_m))
        low, high = -0.5 * length, 0.5 * length
        if room is not None:
            chord = room.chord(foot, along, radius + 0.1)
            if chord is None or chord[1] - chord[0] < 1.0:
                continue
            length = min(length, chord[1] - chord[0])
            low = chord[0] + float(rng.uniform(0.0, chord[1] - chord[0] - length))
            high = low + length
        start, end = foot + low * along, foot + high * along
        radii = np.linalg.norm(
            start + np.linspace(0.0, 1.0, _PATH_SAMPLES)[:, None] * (end - start), axis=1
        )
        if np.all((radii <= band[0] - radius) | (radii >= band[1] + radius)):
            return Walker(kind, dimensions, start, end, speed, phase, reflectivity)
    raise ConfigError(
        f"could not find a walkway for a {kind.value} clear of the robot's path"
        + (" inside the room" if room is not None else "")
        + "; widen the walkers' offset_m or the room"
    )
