"""Solid things in a synthetic world: their kind, role and exact shape.

Every surface the LiDARs can see, except the floor, is a `SceneObject`: low objects, the walls and
shelves of a room, and (placed anew for each scan) the people and carts walking through.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.transforms import Matrix4, to_translation_xyzw


class ObjectKind(enum.StrEnum):
    BOX = "box"
    CYLINDER = "cylinder"
    CAPSULE = "capsule"


class ObjectRole(enum.StrEnum):
    """What an object stands for in the world (all are solid; the role is for scoring)."""

    OBJECT = "object"
    WALL = "wall"
    SHELF = "shelf"
    WALKER = "walker"


@dataclass(frozen=True)
class SceneObject:
    """One object. Its frame has its origin at the centroid and z up.

    `dimensions`: box `x`, `y`, `z` (full sides); cylinder `radius`, `height`; capsule `radius`,
    `length` (straight part, lying along the object's x; total height `2 * radius`).
    """

    kind: ObjectKind
    dimensions: Mapping[str, float]
    T_world_object: Matrix4
    reflectivity: float
    role: ObjectRole = ObjectRole.OBJECT

    @property
    def radius_xy(self) -> float:
        """Radius of the circle round its footprint on the floor."""
        d = self.dimensions
        if self.kind is ObjectKind.BOX:
            return 0.5 * math.hypot(d["x"], d["y"])
        if self.kind is ObjectKind.CYLINDER:
            return d["radius"]
        return 0.5 * d["length"] + d["radius"]

    @property
    def bounding_radius(self) -> float:
        """Radius of a sphere round the centroid that holds the whole object."""
        d = self.dimensions
        if self.kind is ObjectKind.BOX:
            return 0.5 * math.sqrt(d["x"] ** 2 + d["y"] ** 2 + d["z"] ** 2)
        if self.kind is ObjectKind.CYLINDER:
            return math.hypot(d["radius"], 0.5 * d["height"])
        return 0.5 * d["length"] + d["radius"]

    def footprint_gap(self, xy: NDArray[np.float64], radius: float) -> float:
        """Free space between a circle of `radius` at `xy` (2,) and this object's footprint
        (negative where they overlap); exact for boxes, the footprint circle otherwise."""
        centre = self.T_world_object[:2, 3]
        if self.kind is not ObjectKind.BOX:
            return float(np.linalg.norm(xy - centre)) - self.radius_xy - radius
        local = self.T_world_object[:2, :2].T @ (xy - centre)
        half = 0.5 * np.array([self.dimensions["x"], self.dimensions["y"]])
        return float(np.linalg.norm(np.maximum(np.abs(local) - half, 0.0))) - radius

    def distance(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Unsigned distance (N,) from world `points` (N, 3) to the object's surface."""
        return np.abs(self.signed_distance(points))

    def signed_distance(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Signed distance (N,) from world `points` (N, 3) to the object's surface: positive
        outside, negative inside (behind the surface a LiDAR sees)."""
        local = (points - self.T_world_object[:3, 3]) @ self.T_world_object[:3, :3]
        d = self.dimensions
        if self.kind is ObjectKind.BOX:
            excess = np.abs(local) - 0.5 * np.array([d["x"], d["y"], d["z"]])
        elif self.kind is ObjectKind.CYLINDER:
            excess = np.column_stack(
                [
                    np.hypot(local[:, 0], local[:, 1]) - d["radius"],
                    np.abs(local[:, 2]) - 0.5 * d["height"],
                ]
            )
        else:
            axis = np.clip(local[:, 0], -0.5 * d["length"], 0.5 * d["length"])
            offset = local - np.column_stack([axis, np.zeros_like(axis), np.zeros_like(axis)])
            return np.asarray(np.linalg.norm(offset, axis=1) - d["radius"], dtype=np.float64)
        outside = np.linalg.norm(np.maximum(excess, 0.0), axis=1)
        inside = np.all(excess <= 0.0, axis=1)
        return np.asarray(np.where(inside, np.max(excess, axis=1), outside), dtype=np.float64)

    def to_json(self) -> dict[str, object]:
        translation, quat = to_translation_xyzw(self.T_world_object)
        return {
            "kind": self.kind.value,
            "dimensions": dict(self.dimensions),
            "pose": {"translation": translation.tolist(), "rotation_xyzw": quat.tolist()},
            "reflectivity": self.reflectivity,
            "role": self.role.value,
        }
