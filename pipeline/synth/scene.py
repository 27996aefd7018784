"""The MuJoCo world the LiDARs look at: a floor, objects drawn from a seed, and the robot body.

Objects stand on the floor in rings around the robot's path, spread evenly in angle (one random
angle per sector) so that every LiDAR sees some from almost every stop, and never inside the
band the robot's footprint sweeps. Options compose further worlds: a closed room (`room.py`),
people or carts walking through (`walkers.py`), an uneven floor (`floor.py`) and dust (`dust.py`);
left unset, a scene is exactly what it was before they existed.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import mujoco
import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, model_validator
from scipy.spatial.transform import Rotation

from pipeline.errors import ConfigError
from pipeline.synth.dust import DustSpec
from pipeline.synth.floor import FloorSpec, FloorSurface
from pipeline.synth.objects import ObjectKind, ObjectRole, SceneObject
from pipeline.synth.room import RoomSpec
from pipeline.synth.walkers import Walker, WalkersSpec
from pipeline.transforms import (
    Matrix4,
    from_xyz_rpy,
    invert,
    make_transform,
    to_translation_xyzw,
)

__all__ = ["ObjectKind", "ObjectRole", "Ring", "Scene", "SceneObject", "SceneSpec"]

_FROZEN = ConfigDict(frozen=True, extra="forbid")
_PLACEMENT_TRIES = 200
ROBOT_BODY = "robot"
FLOOR_GEOM = "floor"
# MuJoCo geom group of a plane that stands for an analytic floor: rays skip it.
_ANALYTIC_GROUP = 3
NOT_STATIC = -2
"""`Scene.geom_object` of a walker's geom, and the labels' `object_index` of a point on a walker
or on dust: on no static surface."""
FreeFn = Callable[[NDArray[np.float64], float], bool]
"""`(xy (2,), radius) -> whether a circle there keeps clear of the world's other structures`."""


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
    room: RoomSpec | None = Field(default=None, description="walls, doorways and shelves")
    walkers: WalkersSpec | None = Field(default=None, description="people or carts walking by")
    floor: FloorSpec | None = Field(default=None, description="an uneven floor; None: z = 0")
    dust: DustSpec | None = Field(default=None, description="spurious returns near the sensor")

    def robot_band(self, keep_out: tuple[float, float]) -> tuple[float, float]:
        """Inner and outer radius of the ring the robot's footprint sweeps (with its clearance)
        when its centre stays between the radii `keep_out`."""
        robot_radius = 0.5 * math.hypot(self.robot_size_m[0], self.robot_size_m[1])
        return (
            keep_out[0] - robot_radius - self.robot_clearance_m,
            keep_out[1] + robot_radius + self.robot_clearance_m,
        )


@dataclass(frozen=True, eq=False)
class Scene:
    """A built MuJoCo model and what each geom is.

    `geom_object[g]`: index into `objects` of geom `g`, -1 for the floor (and the robot, whose
    body the rays exclude), `NOT_STATIC` for a walker's. `geom_walker[g]`: index into `walkers`, -1
    for every other geom. `object_geom[k]`: geom of surface `k` (the objects, then the walkers,
    as `surfaces` lists them) and of the floor at `k = -1` (the last entry), so it inverts
    `nearest_surface`. `geom_reflectivity[g]`: in (0, 1]. `floor`: the analytic floor the rays
    hit instead of the plane `z = 0`, or None. `ray_groups`: the geom groups rays see (None: all).
    """

    model: mujoco.MjModel
    data: mujoco.MjData
    objects: tuple[SceneObject, ...]
    robot_body_id: int
    geom_object: NDArray[np.int32]
    object_geom: NDArray[np.int32]
    geom_reflectivity: NDArray[np.float64]
    floor: FloorSurface | None = None
    walkers: tuple[Walker, ...] = ()
    geom_walker: NDArray[np.int32] = field(default_factory=lambda: np.zeros(0, dtype=np.int32))
    ray_groups: NDArray[np.uint8] | None = None
    _placed_rotation: NDArray[np.float64] = field(default_factory=lambda: np.full((3, 3), np.nan))
    _walkers_now: list[SceneObject] = field(default_factory=list)
    _walkers_time: list[float] = field(default_factory=lambda: [math.nan])

    @property
    def surfaces(self) -> tuple[SceneObject, ...]:
        """Every solid surface but the floor, where it is now: the objects, then the walkers."""
        return (*self.objects, *self._walkers_now)

    def floor_height(self, xy: NDArray[np.float64]) -> NDArray[np.float64]:
        """Floor height (N,) at world `xy` (N, 2)."""
        if self.floor is None:
            return np.zeros(len(xy))
        return self.floor.height(xy)

    def nearest_surface(
        self, points: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.int16]]:
        """For world `points` (N, 3): distance (N,) to the nearest surface (floor or one of
        `surfaces`) and that surface's index (N,) into `surfaces`, -1 for the floor. Analytic,
        independent of MuJoCo (the floor's distance is the height above it)."""
        if self.floor is None:
            distance = np.abs(points[:, 2])
        else:
            distance = np.abs(points[:, 2] - self.floor.height(points[:, :2]))
        nearest = np.full(len(points), -1, dtype=np.int16)
        for index, obj in enumerate(self.surfaces):
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

    def place_walkers(self, t: float) -> None:
        """Move every walker to where it is at time `t` (seconds since the recording started)."""
        if not self.walkers or self._walkers_time[0] == t:
            return
        self._walkers_now[:] = [
            walker.at(t, float(self.floor_height(walker.positions(np.array([t]))[0])[0]))
            for walker in self.walkers
        ]
        for index, now in enumerate(self._walkers_now):
            mocap = self.model.body_mocapid[self.model.body(_walker_body(index)).id]
            self.data.mocap_pos[mocap] = now.T_world_object[:3, 3]
            mujoco.mju_mat2Quat(
                self.data.mocap_quat[mocap],
                np.ascontiguousarray(now.T_world_object[:3, :3]).ravel(),
            )
        self._walkers_time[0] = t
        mujoco.mj_forward(self.model, self.data)


def place_objects(
    spec: SceneSpec,
    rng: np.random.Generator,
    keep_out: tuple[float, float],
    free: FreeFn | None = None,
) -> tuple[SceneObject, ...]:
    """Draw the objects. `keep_out`: inner and outer radius of the robot centre's path; `free`:
    whether a footprint circle keeps clear of the room and the walkers' ways (None: no such).
    A ring's sector that a wall, shelf or walkway leaves no room in stays empty, and a given
    object (`spec.objects`) standing where one is is left out."""
    band = spec.robot_band(keep_out)
    placed: list[SceneObject] = [
        obj
        for obj in (given.to_object() for given in spec.objects)
        if free is None or free(obj.T_world_object[:2, 3], obj.radius_xy + spec.object_gap_m)
    ]
    for ring in spec.rings:
        count = int(rng.integers(ring.count[0], ring.count[1] + 1))
        offset = rng.random() * 2.0 * math.pi
        for sector in range(count):
            obj = _place_one(spec, rng, ring, band, placed, offset, sector, count, free)
            if obj is not None:
                placed.append(obj)
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
    free: FreeFn | None,
) -> SceneObject | None:
    """One object in its sector; None where the sector's only free floor is taken by the room
    or a walkway (objects are not put where people walk), an error where it is too crowded."""
    blocked = False
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
        if free is not None and not free(xy, r_xy + spec.object_gap_m):
            blocked = True
            continue
        T = candidate.T_world_object.copy()
        T[:2, 3] = xy
        return SceneObject(candidate.kind, candidate.dimensions, T, candidate.reflectivity)
    if blocked:
        return None
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
    *,
    floor: FloorSurface | None = None,
    walkers: Sequence[Walker] = (),
) -> Scene:
    """The MuJoCo model of the floor, `objects`, `walkers` (mocap bodies, placed by
    `Scene.place_walkers`) and the robot (with a site per LiDAR mount). With an analytic
    `floor` the plane stays in the model for its geom id but rays skip it."""
    xml = _world_xml(
        spec, objects, lidar_mounts or {}, analytic_floor=floor is not None, walkers=walkers
    )
    model = mujoco.MjModel.from_xml_string(xml)
    geoms = _GeomTables.of(model, spec, objects, walkers)
    groups = None
    if floor is not None:
        groups = np.ones(6, dtype=np.uint8)
        groups[_ANALYTIC_GROUP] = 0
    scene = Scene(
        model=model,
        data=mujoco.MjData(model),
        objects=tuple(objects),
        robot_body_id=model.body(ROBOT_BODY).id,
        geom_object=geoms.geom_object,
        object_geom=geoms.object_geom,
        geom_reflectivity=geoms.reflectivity,
        floor=floor,
        walkers=tuple(walkers),
        geom_walker=geoms.geom_walker,
        ray_groups=groups,
    )
    scene.place_robot(np.eye(4))
    scene.place_walkers(0.0)
    return scene


def _world_xml(
    spec: SceneSpec,
    objects: Sequence[SceneObject],
    lidar_mounts: Mapping[str, Matrix4],
    *,
    analytic_floor: bool,
    walkers: Sequence[Walker],
) -> str:
    """The MJCF of the world: the floor plane (in the group rays skip, for an analytic floor),
    the objects' geoms, the robot's mocap body with its chassis and a site per LiDAR mount, then
    a mocap body per walker."""
    group = f' group="{_ANALYTIC_GROUP}"' if analytic_floor else ""
    geoms = [
        f'<geom name="{FLOOR_GEOM}" type="plane" size="{_f(spec.floor_half_size_m)} '
        f'{_f(spec.floor_half_size_m)} 0.1"{group}/>'
    ]
    for index, obj in enumerate(objects):
        geoms.append(_geom_xml(f"object_{index}", obj))
    sx, sy, sz = spec.robot_size_m
    robot = [
        f'<geom name="chassis" type="box" size="{_f(sx / 2)} {_f(sy / 2)} {_f(sz / 2)}" '
        f'pos="0 0 {_f(sz / 2)}"/>'
    ]
    for frame, T_base_lidar in lidar_mounts.items():
        robot.append(f'<site name="{frame}" {_pose_xml(T_base_lidar)}/>')
    walker_bodies = [
        f'<body name="{_walker_body(k)}" mocap="true">'
        + _geom_xml(f"walker_{k}", walker.at(0.0), pose=False)
        + "</body>"
        for k, walker in enumerate(walkers)
    ]
    return (
        '<mujoco model="fleetcal-synth"><worldbody>'
        + "".join(geoms)
        + f'<body name="{ROBOT_BODY}" mocap="true">'
        + "".join(robot)
        + "</body>"
        + "".join(walker_bodies)
        + "</worldbody></mujoco>"
    )


@dataclass(frozen=True)
class _GeomTables:
    """What each geom of a built model is (`Scene`'s tables of the same names)."""

    geom_object: NDArray[np.int32]
    geom_walker: NDArray[np.int32]
    object_geom: NDArray[np.int32]
    reflectivity: NDArray[np.float64]

    @classmethod
    def of(
        cls,
        model: mujoco.MjModel,
        spec: SceneSpec,
        objects: Sequence[SceneObject],
        walkers: Sequence[Walker],
    ) -> _GeomTables:
        """Looked up by the names `_world_xml` gave the geoms; every other geom (the floor, the
        chassis) keeps -1 and the floor's reflectivity."""
        geom_object = np.full(model.ngeom, -1, dtype=np.int32)
        geom_walker = np.full(model.ngeom, -1, dtype=np.int32)
        reflectivity = np.full(model.ngeom, spec.floor_reflectivity)
        for index, obj in enumerate(objects):
            geom_id = model.geom(f"object_{index}").id
            geom_object[geom_id] = index
            reflectivity[geom_id] = obj.reflectivity
        walker_geoms = [model.geom(f"walker_{k}").id for k in range(len(walkers))]
        for index, (geom_id, walker) in enumerate(zip(walker_geoms, walkers, strict=True)):
            geom_object[geom_id] = NOT_STATIC
            geom_walker[geom_id] = index
            reflectivity[geom_id] = walker.reflectivity
        object_geom = np.array(
            [model.geom(f"object_{k}").id for k in range(len(objects))]
            + walker_geoms
            + [model.geom(FLOOR_GEOM).id],
            dtype=np.int32,
        )
        return cls(geom_object, geom_walker, object_geom, reflectivity)


def _walker_body(index: int) -> str:
    return f"walker_body_{index}"


def _geom_xml(name: str, obj: SceneObject, pose: bool = True) -> str:
    """The geom of `obj`, at its pose (`pose`) or at its body's origin."""
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
    placement = _pose_xml(T if pose else invert(obj.T_world_object) @ T)
    return f'<geom name="{name}" type="{obj.kind.value}" size="{size}" {placement}/>'


def _pose_xml(T: Matrix4) -> str:
    translation, quat = to_translation_xyzw(T)
    pos = " ".join(_f(v) for v in translation)
    wxyz = " ".join(_f(v) for v in (quat[3], quat[0], quat[1], quat[2]))
    return f'pos="{pos}" quat="{wxyz}"'


def _f(value: float) -> str:
    """Full precision, so the model's geometry is exactly the recorded truth."""
    return repr(float(value))
