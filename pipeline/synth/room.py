"""A closed room round the robot: four walls with doorways, and tall shelves standing along them.

The room is a rectangle in its own frame (yawed in the world), its walls drawn at their own
distances from the origin (the centre of the robot's path), so the robot stands off-centre.
Walls and shelves are box objects with roles, so rays, labels and truth treat them as any other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, model_validator

from pipeline.errors import ConfigError
from pipeline.synth.objects import ObjectKind, ObjectRole, SceneObject
from pipeline.transforms import Matrix4, from_xyz_rpy

_DOOR_TRIES = 50
_CORNER_MARGIN_M = 0.3
# Doorways keep this much wall (and shelf-free floor) between each other and on either side.
_DOOR_CLEARANCE_M = 0.4


class RoomSpec(BaseModel):
    """What the seed draws a room from (every range is uniform; distances to inner faces)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    wall_distance_m: tuple[float, float] = (2.0, 5.0)
    wall_height_m: tuple[float, float] = (2.0, 3.0)
    wall_thickness_m: float = Field(default=0.15, gt=0)
    yaw_deg: tuple[float, float] = (-45.0, 45.0)
    doorways: tuple[int, int] = (1, 2)
    door_width_m: tuple[float, float] = (0.9, 1.6)
    door_height_m: tuple[float, float] = (2.0, 2.2)
    shelf_height_m: tuple[float, float] = (1.5, 2.0)
    shelf_depth_m: tuple[float, float] = (0.4, 0.6)
    shelf_width_m: tuple[float, float] = (0.8, 2.0)
    shelf_fill: float = Field(default=0.6, ge=0, le=1, description="chance a free slot holds one")
    shelf_gap_m: tuple[float, float] = Field(
        default=(0.02, 0.08), description="free space between a shelf and its wall"
    )
    wall_reflectivity: tuple[float, float] = (0.3, 0.7)
    shelf_reflectivity: tuple[float, float] = (0.05, 0.9)

    @model_validator(mode="after")
    def _check(self) -> RoomSpec:
        for name, value in self:
            if isinstance(value, tuple) and name != "yaw_deg" and not 0 <= value[0] <= value[1]:
                raise ValueError(f"room {name} must be (low, high) with 0 <= low <= high")
        if self.wall_distance_m[0] <= self.shelf_depth_m[1] + self.shelf_gap_m[1]:
            raise ValueError("room walls must stand farther from the origin than a shelf is deep")
        return self


@dataclass(frozen=True)
class Room:
    """A drawn room: `T_world_room` (4, 4), the inner faces' bounds in the room frame
    `(x_min, x_max, y_min, y_max)`, the free floor's bounds (inside the deepest shelves), and
    its walls, lintels and shelves."""

    T_world_room: Matrix4
    inner: tuple[float, float, float, float]
    free: tuple[float, float, float, float]
    structures: tuple[SceneObject, ...]

    def gap(self, xy: NDArray[np.float64], radius: float) -> float:
        """Free space between a circle (`xy` (2,) world, `radius`) and the room's walls and
        shelves; negative where it overlaps one or lies outside the room."""
        x, y = (float(v) for v in self.T_world_room[:2, :2].T @ (xy - self.T_world_room[:2, 3]))
        x_min, x_max, y_min, y_max = self.inner
        inside = min(x - x_min, x_max - x, y - y_min, y_max - y)
        return min([inside - radius, *(s.footprint_gap(xy, radius) for s in self.structures)])

    def chord(
        self, point: NDArray[np.float64], direction: NDArray[np.float64], margin: float
    ) -> tuple[float, float] | None:
        """Where the world line `point + s * direction` runs over the free floor shrunk by
        `margin`: `(s_start, s_end)`, or None where it misses it."""
        R = self.T_world_room[:2, :2]
        p = R.T @ (point - self.T_world_room[:2, 3])
        d = R.T @ direction
        x_min, x_max, y_min, y_max = self.free
        low, high = -math.inf, math.inf
        for axis, (a, b) in enumerate(
            ((x_min + margin, x_max - margin), (y_min + margin, y_max - margin))
        ):
            if abs(d[axis]) < 1e-12:
                if not a <= p[axis] <= b:
                    return None
                continue
            s0, s1 = sorted(((a - p[axis]) / d[axis], (b - p[axis]) / d[axis]))
            low, high = max(low, s0), min(high, s1)
        return (low, high) if low < high else None


def build_room(spec: RoomSpec, rng: np.random.Generator, band: tuple[float, float]) -> Room:
    """Draw a room. `band`: inner and outer radius of the ring the robot's footprint sweeps
    (with its clearance); no wall or shelf may reach into it."""
    yaw = math.radians(rng.uniform(*spec.yaw_deg))
    east, north, west, south = rng.uniform(*spec.wall_distance_m, size=4)
    height = float(rng.uniform(*spec.wall_height_m))
    inner = (-float(west), float(east), -float(south), float(north))
    T_world_room = from_xyz_rpy([0.0, 0.0, 0.0], [0.0, 0.0, yaw])
    walls = _walls(inner, spec.wall_thickness_m)
    doors = _doorways(spec, rng, walls)
    structures: list[SceneObject] = []
    for index, wall in enumerate(walls):
        reflectivity = float(rng.uniform(*spec.wall_reflectivity))
        mine = sorted(door for door in doors if door[0] == index)
        structures += _wall_boxes(wall, mine, height, reflectivity, T_world_room)
        structures += _shelves(spec, rng, wall, mine, T_world_room)
    depth = spec.shelf_depth_m[1] + spec.shelf_gap_m[1]
    free = (inner[0] + depth, inner[1] - depth, inner[2] + depth, inner[3] - depth)
    room = Room(T_world_room, inner, free, tuple(structures))
    for structure in room.structures:
        nearest = structure.footprint_gap(np.zeros(2), 0.0)
        if nearest < band[1]:
            raise ConfigError(
                f"a {structure.role.value} of the room stands {nearest:.2f} m from the centre of "
                f"the robot's path, inside the {band[1]:.2f} m its footprint sweeps; raise the "
                "room's wall_distance_m or make its shelves shallower"
            )
    return room


@dataclass(frozen=True)
class _Wall:
    """One wall in the room frame: its inner face runs from `start` (2,) along `along` (2,) for
    `length` m; `inward` (2,) points into the room. `inner_span` is the stretch along it that
    faces the room (the rest closes the corners)."""

    start: NDArray[np.float64]
    along: NDArray[np.float64]
    inward: NDArray[np.float64]
    length: float
    inner_span: tuple[float, float]
    thickness: float


def _walls(inner: tuple[float, float, float, float], thickness: float) -> list[_Wall]:
    """East, north, west, south walls; each runs past both corners by the wall's thickness."""
    x_min, x_max, y_min, y_max = inner
    t = thickness
    specs = [
        ((x_max, y_min - t), (0.0, 1.0), (-1.0, 0.0), y_max - y_min),
        ((x_max + t, y_max), (-1.0, 0.0), (0.0, -1.0), x_max - x_min),
        ((x_min, y_max + t), (0.0, -1.0), (1.0, 0.0), y_max - y_min),
        ((x_min - t, y_min), (1.0, 0.0), (0.0, 1.0), x_max - x_min),
    ]
    return [
        _Wall(np.array(start), np.array(along), np.array(inward), span + 2 * t, (t, t + span), t)
        for start, along, inward, span in specs
    ]


def _doorways(
    spec: RoomSpec, rng: np.random.Generator, walls: list[_Wall]
) -> list[tuple[int, float, float, float]]:
    """Doorways as `(wall index, start, end along the wall, height)`, apart from each other
    and from the corners."""
    count = int(rng.integers(spec.doorways[0], spec.doorways[1] + 1))
    doors: list[tuple[int, float, float, float]] = []
    for _ in range(count):
        for _ in range(_DOOR_TRIES):
            index = int(rng.integers(len(walls)))
            width = float(rng.uniform(*spec.door_width_m))
            low, high = walls[index].inner_span
            low, high = low + _CORNER_MARGIN_M, high - _CORNER_MARGIN_M - width
            if high <= low:
                continue
            start = float(rng.uniform(low, high))
            end = start + width
            if all(
                other[0] != index
                or end + _DOOR_CLEARANCE_M < other[1]
                or other[2] + _DOOR_CLEARANCE_M < start
                for other in doors
            ):
                doors.append((index, start, end, float(rng.uniform(*spec.door_height_m))))
                break
    return doors


def _wall_boxes(
    wall: _Wall,
    doors: list[tuple[int, float, float, float]],
    height: float,
    reflectivity: float,
    T_world_room: Matrix4,
) -> list[SceneObject]:
    """The wall's solid stretches between its doorways, and a lintel over each doorway."""
    boxes = []
    cursor = 0.0
    for _, start, end, door_height in [*doors, (0, wall.length, wall.length, 0.0)]:
        if start > cursor:
            boxes.append(_box(wall, cursor, start, 0.0, height, 0.0, wall.thickness, reflectivity))
        if door_height and height - door_height > 0.05:
            boxes.append(
                _box(wall, start, end, door_height, height, 0.0, wall.thickness, reflectivity)
            )
        cursor = end
    return [_in_world(box, T_world_room, ObjectRole.WALL) for box in boxes]


def _shelves(
    spec: RoomSpec,
    rng: np.random.Generator,
    wall: _Wall,
    doors: list[tuple[int, float, float, float]],
    T_world_room: Matrix4,
) -> list[SceneObject]:
    """Shelves side by side along the wall's inner face, leaving the corners and doorways free."""
    depth_max = spec.shelf_depth_m[1] + spec.shelf_gap_m[1]
    cursor, end = wall.inner_span[0] + depth_max, wall.inner_span[1] - depth_max
    shelves = []
    while True:
        width = float(rng.uniform(*spec.shelf_width_m))
        if cursor + width > end:
            break
        blocked = any(
            cursor < door_end + _DOOR_CLEARANCE_M
            and door_start - _DOOR_CLEARANCE_M < cursor + width
            for _, door_start, door_end, _ in doors
        )
        if not blocked and rng.random() < spec.shelf_fill:
            gap = float(rng.uniform(*spec.shelf_gap_m))
            depth = float(rng.uniform(*spec.shelf_depth_m))
            shelf_height = float(rng.uniform(*spec.shelf_height_m))
            reflectivity = float(rng.uniform(*spec.shelf_reflectivity))
            box = _box(
                wall, cursor, cursor + width, 0.0, shelf_height, -gap, -gap - depth, reflectivity
            )
            shelves.append(_in_world(box, T_world_room, ObjectRole.SHELF))
            cursor += width + float(rng.uniform(0.05, 0.5))
        else:
            cursor += float(rng.uniform(0.3, 1.0))
    return shelves


def _box(
    wall: _Wall,
    start: float,
    end: float,
    bottom: float,
    top: float,
    front: float,
    back: float,
    reflectivity: float,
) -> SceneObject:
    """A box along `wall` from `start` to `end`, `bottom` to `top`, between `front` and `back`
    (signed distances behind the inner face: positive into the wall), in the room frame."""
    middle = wall.start + wall.along * 0.5 * (start + end) - wall.inward * 0.5 * (front + back)
    yaw = math.atan2(wall.along[1], wall.along[0])
    dimensions = {"x": end - start, "y": abs(back - front), "z": top - bottom}
    T = from_xyz_rpy([middle[0], middle[1], 0.5 * (bottom + top)], [0.0, 0.0, yaw])
    return SceneObject(ObjectKind.BOX, dimensions, T, reflectivity)


def _in_world(box: SceneObject, T_world_room: Matrix4, role: ObjectRole) -> SceneObject:
    return SceneObject(
        box.kind, box.dimensions, T_world_room @ box.T_world_object, box.reflectivity, role
    )
