"""The MuJoCo world the LiDARs look at: a floor, objects drawn from a seed, and the robot body.

Objects stand on the floor in rings around the robot's path, spread evenly in angle (one random
angle per sector) so that every LiDAR sees some from almost every stop, and never inside the
band the robot's footprint sweeps.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import mujoco
import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, model_validator
from scipy.spatial.transform import Rotation

from pipeline.errors import ConfigError
from pipeline.transforms import Matrix4, from_xyz_rpy, make_transform, to_translation_xyzw

_FROZEN = ConfigDict(frozen=True, extra="forbid")
_PLACEMENT_TRIES = 200
ROBOT_BODY = "robot"
FLOOR_GEOM = "floor"


class ObjectKind(enum.StrEnum):
    BOX = "box"
    CYLINDER = "cylinder"
    CAPSULE = "capsule"


class Ring(BaseModel):
    """Objects placed with their centres at a radius in `[r_min_m, r_max_m]` from the origin."""

    model_config = _FROZEN

    r_min_m: float = Field(ge=0)
    r_max_m: float = Field(gt=0)
    count: tuple[int, int] = Field(description="fewest and most objects, drawn uniformly")

    @model_validator(mode="after")
    def _check(self) -> Ring:
        if self.r_min_m >= self.r_max_m or not 0 <= self.count[0] <= self.count[1]:
            raise ValueError(f"ring needs r_min < r_max and 0 <= count[0] <= count[1]; got {self}")
        return self


class PlacedObject(BaseModel):
    """An object whose every detail is given (a randomised scenario draws them itself): its kind,
    `dimensions` as `SceneObject`'s, the centre of its footprint `xy` (m) and its yaw (deg); it
    stands on the floor."""

    model_config = _FROZEN

    kind: ObjectKind
    dimensions: dict[str, float]
    xy: tuple[float, float]
    yaw_deg: float = 0.0
    reflectivity: float = Field(default=0.6, gt=0, le=1)

    @property
    def height_m(self) -> float:
        d = self.dimensions
        if self.kind is ObjectKind.BOX:
            return d["z"]
        return d["height"] if self.kind is ObjectKind.CYLINDER else 2.0 * d["radius"]

    def to_object(self) -> SceneObject:
        T = from_xyz_rpy([*self.xy, self.height_m / 2.0], [0.0, 0.0, math.radians(self.yaw_deg)])
        return SceneObject(self.kind, dict(self.dimensions), T, self.reflectivity)


class SceneSpec(BaseModel):
    """What the world holds; the seed decides the details (count, kind, size, place) of the
    objects in `rings`; `objects` are placed as given."""

    model_config = _FROZEN

    objects: tuple[PlacedObject, ...] = ()
    object_kinds: tuple[ObjectKind, ...] = (ObjectKind.BOX,)
    rings: tuple[Ring, ...] = (Ring(r_min_m=1.0, r_max_m=2.6, count=(8, 12)),)
    object_height_m: float = Field(default=0.25, gt=0)
    box_side_m: tuple[float, float] = (0.2, 0.5)
    cylinder_radius_m: tuple[float, float] = (0.1, 0.25)
    capsule_length_m: tuple[float, float] = Field(
        default=(0.2, 0.5), description="straight part of a capsule lying on its side"
    )
    object_gap_m: float = Field(default=0.3, ge=0, description="free space between objects")
    robot_clearance_m: float = Field(
        default=0.3, ge=0, description="free space around the robot's path"
    )
    floor_half_size_m: float = Field(default=12.0, gt=0)
    floor_reflectivity: float = Field(default=0.15, gt=0, le=1)
    object_reflectivity: tuple[float, float] = (0.4, 0.8)
    robot_size_m: tuple[float, float, float] = (0.7, 0.5, 0.45)


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

    def distance(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Unsigned distance (N,) from world `points` (N, 3) to the object's surface."""
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
            return np.asarray(np.abs(np.linalg.norm(offset, axis=1) - d["radius"]))
        outside = np.linalg.norm(np.maximum(excess, 0.0), axis=1)
        inside = np.all(excess <= 0.0, axis=1)
        return np.asarray(np.where(inside, -np.max(excess, axis=1), outside), dtype=np.float64)

    def to_json(self) -> dict[str, object]:
        translation, quat = to_translation_xyzw(self.T_world_object)
        return {
            "kind": self.kind.value,
            "dimensions": dict(self.dimensions),
            "pose": {"translation": translation.tolist(), "rotation_xyzw": quat.tolist()},
            "reflectivity": self.reflectivity,
        }


@dataclass(frozen=True, eq=False)
class Scene:
    """A built MuJoCo model and what each geom is.

    `geom_object[g]`: index into `objects` of geom `g`, -1 for the floor (and the robot, whose
    body the rays exclude). `object_geom[k]`: geom of object `k`, and of the floor at `k = -1`
    (the last entry), so it inverts `geom_object`. `geom_reflectivity[g]`: in (0, 1].
    """

    model: mujoco.MjModel
    data: mujoco.MjData
    objects: tuple[SceneObject, ...]
    robot_body_id: int
    geom_object: NDArray[np.int32]
    object_geom: NDArray[np.int32]
    geom_reflectivity: NDArray[np.float64]
    _placed_rotation: NDArray[np.float64] = field(default_factory=lambda: np.full((3, 3), np.nan))

    def nearest_surface(
        self, points: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.int16]]:
        """For world `points` (N, 3): distance (N,) to the nearest surface (floor or object) and
        that surface's object index (N,), -1 for the floor. Analytic, independent of MuJoCo."""
        distance = np.abs(points[:, 2])
        nearest = np.full(len(points), -1, dtype=np.int16)
        for index, obj in enumerate(self.objects):
            # Only points that could beat the current best need the exact distance.
            to_centre = np.linalg.norm(points - obj.T_world_object[:3, 3], axis=1)
            rows = np.flatnonzero(to_centre - obj.bounding_radius < distance)
            if len(rows) == 0:
                continue
            candidate = obj.distance(points[rows])
            better = candidate < distance[rows]
            distance[rows[better]] = candidate[better]
            nearest[rows[better]] = index
        return distance, nearest

    def place_robot(self, T_world_base: Matrix4) -> None:
        """Move the robot body (a mocap body) and recompute the world's geometry."""
        if np.array_equal(self.data.mocap_pos[0], T_world_base[:3, 3]) and np.array_equal(
            self._placed_rotation, T_world_base[:3, :3]
        ):
            return
        self.data.mocap_pos[0] = T_world_base[:3, 3]
        mujoco.mju_mat2Quat(
            self.data.mocap_quat[0], np.ascontiguousarray(T_world_base[:3, :3]).ravel()
        )
        self._placed_rotation[:] = T_world_base[:3, :3]
        # Ray casting reads geom poses from the data; without a forward pass every ray misses.
        mujoco.mj_forward(self.model, self.data)


def place_objects(
    spec: SceneSpec, rng: np.random.Generator, keep_out: tuple[float, float]
) -> tuple[SceneObject, ...]:
    """Draw the objects. `keep_out`: inner and outer radius of the robot centre's path."""
    robot_radius = 0.5 * math.hypot(spec.robot_size_m[0], spec.robot_size_m[1])
    band = (
        keep_out[0] - robot_radius - spec.robot_clearance_m,
        keep_out[1] + robot_radius + spec.robot_clearance_m,
    )
    placed: list[SceneObject] = [obj.to_object() for obj in spec.objects]
    for ring in spec.rings:
        count = int(rng.integers(ring.count[0], ring.count[1] + 1))
        offset = rng.random() * 2.0 * math.pi
        for sector in range(count):
            placed.append(_place_one(spec, rng, ring, band, placed, offset, sector, count))
    return tuple(placed)


def _place_one(
    spec: SceneSpec,
    rng: np.random.Generator,
    ring: Ring,
    band: tuple[float, float],
    placed: Sequence[SceneObject],
    offset: float,
    sector: int,
    count: int,
) -> SceneObject:
    for _ in range(_PLACEMENT_TRIES):
        candidate = _draw_object(spec, rng)
        angle = offset + 2.0 * math.pi * (sector + rng.uniform(0.1, 0.9)) / count
        radius = math.sqrt(rng.uniform(ring.r_min_m**2, ring.r_max_m**2))
        xy = radius * np.array([math.cos(angle), math.sin(angle)])
        r_xy = candidate.radius_xy
        if band[0] - r_xy < radius < band[1] + r_xy:
            continue
        if any(
            np.linalg.norm(xy - other.T_world_object[:2, 3])
            < r_xy + other.radius_xy + spec.object_gap_m
            for other in placed
        ):
            continue
        T = candidate.T_world_object.copy()
        T[:2, 3] = xy
        return SceneObject(candidate.kind, candidate.dimensions, T, candidate.reflectivity)
    raise ConfigError(
        f"could not place {count} objects in the ring {ring.r_min_m}-{ring.r_max_m} m without "
        "overlaps or touching the robot's path; widen the ring or lower its object count"
    )


def _draw_object(spec: SceneSpec, rng: np.random.Generator) -> SceneObject:
    """An object of a random kind and size, at the origin with a random yaw."""
    kind = spec.object_kinds[int(rng.integers(len(spec.object_kinds)))]
    height = spec.object_height_m
    dimensions: dict[str, float]
    if kind is ObjectKind.BOX:
        x, y = rng.uniform(*spec.box_side_m, size=2)
        dimensions = {"x": float(x), "y": float(y), "z": height}
    elif kind is ObjectKind.CYLINDER:
        dimensions = {"radius": float(rng.uniform(*spec.cylinder_radius_m)), "height": height}
    else:
        dimensions = {"radius": height / 2.0, "length": float(rng.uniform(*spec.capsule_length_m))}
    yaw = rng.uniform(-math.pi, math.pi)
    reflectivity = float(rng.uniform(*spec.object_reflectivity))
    return SceneObject(
        kind, dimensions, from_xyz_rpy([0.0, 0.0, height / 2.0], [0, 0, yaw]), reflectivity
    )


def build_scene(
    spec: SceneSpec,
    objects: Sequence[SceneObject],
    lidar_mounts: Mapping[str, Matrix4] | None = None,
) -> Scene:
    """The MuJoCo model of the floor, `objects` and the robot (with a site per LiDAR mount)."""
    geoms = [
        f'<geom name="{FLOOR_GEOM}" type="plane" size="{_f(spec.floor_half_size_m)} '
        f'{_f(spec.floor_half_size_m)} 0.1"/>'
    ]
    for index, obj in enumerate(objects):
        geoms.append(_geom_xml(f"object_{index}", obj))
    sx, sy, sz = spec.robot_size_m
    robot = [
        f'<geom name="chassis" type="box" size="{_f(sx / 2)} {_f(sy / 2)} {_f(sz / 2)}" '
        f'pos="0 0 {_f(sz / 2)}"/>'
    ]
    for frame, T_base_lidar in (lidar_mounts or {}).items():
        robot.append(f'<site name="{frame}" {_pose_xml(T_base_lidar)}/>')
    xml = (
        '<mujoco model="fleetcal-synth"><worldbody>'
        + "".join(geoms)
        + f'<body name="{ROBOT_BODY}" mocap="true">'
        + "".join(robot)
        + "</body></worldbody></mujoco>"
    )
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    geom_object = np.full(model.ngeom, -1, dtype=np.int32)
    reflectivity = np.full(model.ngeom, spec.floor_reflectivity)
    for index, obj in enumerate(objects):
        geom_id = model.geom(f"object_{index}").id
        geom_object[geom_id] = index
        reflectivity[geom_id] = obj.reflectivity
    scene = Scene(
        model=model,
        data=data,
        objects=tuple(objects),
        robot_body_id=model.body(ROBOT_BODY).id,
        geom_object=geom_object,
        object_geom=np.array(
            [model.geom(f"object_{k}").id for k in range(len(objects))]
            + [model.geom(FLOOR_GEOM).id],
            dtype=np.int32,
        ),
        geom_reflectivity=reflectivity,
    )
    scene.place_robot(np.eye(4))
    return scene


def _geom_xml(name: str, obj: SceneObject) -> str:
    d = obj.dimensions
    T = obj.T_world_object
    if obj.kind is ObjectKind.BOX:
        size = f"{_f(d['x'] / 2)} {_f(d['y'] / 2)} {_f(d['z'] / 2)}"
    elif obj.kind is ObjectKind.CYLINDER:
        size = f"{_f(d['radius'])} {_f(d['height'] / 2)}"
    else:
        size = f"{_f(d['radius'])} {_f(d['length'] / 2)}"
        # MuJoCo's capsule runs along its own z; lay it along the object's x.
        T = T @ make_transform(Rotation.from_euler("y", 90, degrees=True).as_matrix(), np.zeros(3))
    return f'<geom name="{name}" type="{obj.kind.value}" size="{size}" {_pose_xml(T)}/>'


def _pose_xml(T: Matrix4) -> str:
    translation, quat = to_translation_xyzw(T)
    pos = " ".join(_f(v) for v in translation)
    wxyz = " ".join(_f(v) for v in (quat[3], quat[0], quat[1], quat[2]))
    return f'pos="{pos}" quat="{wxyz}"'


def _f(value: float) -> str:
    """Full precision, so the model's geometry is exactly the recorded truth."""
    return repr(float(value))
