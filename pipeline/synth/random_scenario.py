"""Randomised scenarios: a seed draws a whole robot, routine, scene and set of errors.

`random_scenario(seed)` returns a frozen `ScenarioSpec` (everything written to `truth.json`);
`fleetcal synth random --seed N` writes it. Each draw is labelled with a benchmark class
`routine/sensors/errors`. Every factor comes from the table `RANGES` (below, and in code):

| factor | range |
|---|---|
| routine | rotate (in place), loop (square or rectangle), figure-eight, lane (back and forth) |
| rotate: stops; step between stops | 8-24; 15-45 deg |
| loop: sides (equal for a square, half the loops) | 1-4 m |
| loop, lane, figure-eight: a stop every | 0.5-1.5 m of path |
| figure-eight: circle radius | 0.8-1.5 m |
| lane: length | 2-5 m |
| stop duration (a sub-range per recording, each stop drawn in it) | 0.4-3 s |
| peak drive speed; peak turn rate (minimum-jerk ramps) | 0.2-0.8 m/s; 20-60 deg/s |
| sensors | rosette (Mid-70, Mid-360-like), spinning (16, 32, 64 beams), mixed (both) |
| LiDARs per robot | 2-5 |
| spinning: beam field | ring, channel, laser_id, none |
| spinning: azimuth kept (centred ahead) | 120-360 deg |
| Mid-360-like: `line` field | yes, no |
| mount height; tilt down; roll; yaw | 0.3-1.5 m; 0-45 deg; -10..+10 deg; any |
| mount yaws at least this far apart | 30 deg |
| objects: count; height; distance from the path | 4-16; 0.2-1.0 m; 1-4 m |
| objects: kinds | box, cylinder, capsule (lying, as tall as it is wide) |
| objects: box side; cylinder radius; capsule length | 0.2-0.6 m; 0.1-0.3 m; 0.2-0.6 m |
| objects: reflectivity | 0.2-0.9 |
| errors: initial extrinsics, bound (small / large class) | 0.2 m, 5 deg / 0.5 m, 15 deg |
| errors: odometry per stop, bound | 0-0.2 m; 0-3 deg |
| errors: odometry drift at the route's end (planar) | 0-0.2 m; 0-3 deg |
| clock | synced, simulated, lidar-offset |
| simulated: header clock at the recording's start | 0-3600 s |
| lidar-offset: each LiDAR's header clock off by (one or more LiDARs) | -180..-30 days |
| world (only where asked for, `world=`) | open, room, people, uneven-floor, dust, factory |
| room: walls from the path's start (farther where the path reaches: below) | 2-5 m |
| room: wall height; shelf height; doorways | 2-3 m; 1.5-2 m; 1-2 |
| people: walkers; speed | 1-3; 0.5-1.5 m/s |
| people: walkway from the path's start (farther where the path reaches: below) | 1-3.5 m |
| uneven floor: wave amplitude; wavelength; slope; joint | 3-5 mm; 1-3 m; 0.2-0.5 deg; 2-5 mm |
| dust: share of returns; range | 0.3 %; 0.1-1.5 m |

A Mid-360-like head hangs upside down (roll 180 deg plus the drawn roll), as robots mount it to
see the floor. A LiDAR sits on the chassis outline in the direction it faces. Objects stand
clear of the robot's swept path (its half-diagonal plus 0.3 m plus their own footprint) and
0.3 m apart. Each concern draws from its own random stream, so a new axis leaves the others'
draws alone.

The world (issue 14) is an opt-in axis: `random_scenario(seed)` (and `fleetcal synth random`
without `--world`) is the open floor, exactly as before the axis existed. `world=NAME` puts the
same robot, routine, objects, errors and clocks into that world (`factory`: a room, people and
carts, an uneven floor and dust at once); `world="random"` draws it from the seed's own world
stream. The class gains the world (`rotate/rosette/small/room`), `spec.world` names it, and the
scene holds its options (`SceneSpec.room`, `walkers`, `floor`, `dust`), whose details the seed
draws when the world is made. The room is centred on the path's start, so its walls stand at
least the path's reach, plus a shelf's depth, plus an aisle (0.3 m; 1.5 m where people walk)
away; likewise a walkway keeps the path's reach plus the walker's size away. Objects a wall,
shelf or walkway takes the place of are left out (the truth's `objects` lists those placed).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from pydantic import BaseModel, ConfigDict

from pipeline.errors import ConfigError
from pipeline.synth.dust import DustSpec
from pipeline.synth.floor import FloorSpec
from pipeline.synth.lidar_models import BeamField, LidarModel, Mid70, Mid360, SpinningLidar
from pipeline.synth.motion import RouteMotion
from pipeline.synth.perturbation import PerturbationBounds, PlanarDrift
from pipeline.synth.room import RoomSpec
from pipeline.synth.routines import (
    Speeds,
    figure_eight,
    lane,
    lane_stop_count,
    loop,
    loop_stop_count,
    rotate_in_place,
)
from pipeline.synth.scenarios import LidarMount, ScenarioSpec, WorldKind
from pipeline.synth.scene import ObjectKind, PlacedObject, SceneSpec
from pipeline.synth.walkers import WalkerKind, WalkersSpec

Range = tuple[float, float]
ROUTINES = ("rotate", "loop", "figure-eight", "lane")
SENSOR_MIXES = ("rosette", "spinning", "mixed")
ERROR_SIZES = ("small", "large")
CLOCKS = ("synced", "simulated", "lidar-offset")
BEAM_FIELDS: tuple[BeamField | None, ...] = ("ring", "channel", "laser_id", None)
WORLDS = ("open", "room", "people", "uneven-floor", "dust", "factory")
RANDOM_WORLD = "random"
"""`world=` this draws one of `WORLDS` from the seed."""
_WORLD_KINDS = {
    "open": WorldKind.OPEN_FLOOR,
    "room": WorldKind.ROOM,
    "people": WorldKind.PEOPLE,
    "uneven-floor": WorldKind.UNEVEN_FLOOR,
    "dust": WorldKind.DUST,
    "factory": WorldKind.FACTORY,
}
# Which of the scene's options each world sets.
_WORLD_OPTIONS = {
    "open": (),
    "room": ("room",),
    "people": ("walkers",),
    "uneven-floor": ("floor",),
    "dust": ("dust",),
    "factory": ("room", "walkers", "floor", "dust"),
}
_PLACEMENT_TRIES = 400
_WALKWAY_MARGIN_M = 0.05
_DAY_NS = 86_400 * 1_000_000_000
# Stream ids: one random stream per concern.
_CLASS, _ROUTINE, _LIDARS, _OBJECTS, _ERRORS, _CLOCK, _WORLD = range(7)


class RandomRanges(BaseModel):
    """The table of the module docstring: every range a randomised scenario draws from."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    rotate_stops: tuple[int, int] = (8, 24)
    rotate_step_deg: Range = (15.0, 45.0)
    loop_side_m: Range = (1.0, 4.0)
    stop_spacing_m: Range = (0.5, 1.5)
    figure_eight_radius_m: Range = (0.8, 1.5)
    lane_length_m: Range = (2.0, 5.0)
    dwell_s: Range = (0.4, 3.0)
    drive_mps: Range = (0.2, 0.8)
    turn_dps: Range = (20.0, 60.0)
    lidar_count: tuple[int, int] = (2, 5)
    spinning_azimuth_deg: Range = (120.0, 360.0)
    mount_height_m: Range = (0.3, 1.5)
    mount_tilt_deg: Range = (0.0, 45.0)
    mount_roll_deg: Range = (-10.0, 10.0)
    mount_yaw_deg: Range = (-180.0, 180.0)
    min_yaw_separation_deg: float = 30.0
    object_count: tuple[int, int] = (4, 16)
    object_height_m: Range = (0.2, 1.0)
    object_distance_m: Range = (1.0, 4.0)
    box_side_m: Range = (0.2, 0.6)
    cylinder_radius_m: Range = (0.1, 0.3)
    capsule_length_m: Range = (0.2, 0.6)
    reflectivity: Range = (0.2, 0.9)
    object_gap_m: float = 0.3
    robot_clearance_m: float = 0.3
    extrinsic_small: PerturbationBounds = PerturbationBounds(translation_m=0.2, rotation_deg=5.0)
    extrinsic_large: PerturbationBounds = PerturbationBounds(translation_m=0.5, rotation_deg=15.0)
    odometry_translation_m: Range = (0.0, 0.2)
    odometry_rotation_deg: Range = (0.0, 3.0)
    drift_translation_m: Range = (0.0, 0.2)
    drift_rotation_deg: Range = (0.0, 3.0)
    simulated_start_s: Range = (0.0, 3600.0)
    lidar_clock_offset_days: Range = (-180.0, -30.0)
    room: RoomSpec = RoomSpec()
    room_aisle_m: float = 0.3
    walkway_aisle_m: float = 1.5
    room_wall_spread_m: float = 1.0
    walkers: WalkersSpec = WalkersSpec(count=(1, 3))
    floor: FloorSpec = FloorSpec()
    dust: DustSpec = DustSpec()


RANGES = RandomRanges()


def scenario_class(routine: str, sensors: str, errors: str, world: str | None = None) -> str:
    return f"{routine}/{sensors}/{errors}" + (f"/{world}" if world is not None else "")


def scenario_classes() -> tuple[str, ...]:
    """Every class a draw without a world can have (a world's adds `/WORLD`)."""
    return tuple(
        scenario_class(r, s, e) for r in ROUTINES for s in SENSOR_MIXES for e in ERROR_SIZES
    )


def random_scenario(
    seed: int, ranges: RandomRanges = RANGES, *, world: str | None = None
) -> ScenarioSpec:
    """The scenario `seed` draws (the same for the same seed); see the module docstring.
    `world`: one of `WORLDS` or `RANDOM_WORLD`; None is the open floor with the class and spec
    of the draws made before the world axis existed."""
    if seed < 0:
        raise ConfigError(f"seed must be 0 or more, got {seed}")
    if world is not None and world not in (*WORLDS, RANDOM_WORLD):
        raise ConfigError(
            f"unknown world {world!r}; choose one of: {', '.join(WORLDS)} or {RANDOM_WORLD} "
            "(the seed draws one)"
        )
    rng = np.random.default_rng([seed, _CLASS])
    routine, sensors, errors = (
        str(rng.choice(ROUTINES)),
        str(rng.choice(SENSOR_MIXES)),
        str(rng.choice(ERROR_SIZES)),
    )
    motion = _routine(routine, np.random.default_rng([seed, _ROUTINE]), ranges)
    lidars = _lidars(sensors, np.random.default_rng([seed, _LIDARS]), ranges)
    scene = SceneSpec(
        rings=(),
        objects=_objects(motion, np.random.default_rng([seed, _OBJECTS]), ranges),
        robot_clearance_m=ranges.robot_clearance_m,
        object_gap_m=ranges.object_gap_m,
    )
    rng = np.random.default_rng([seed, _ERRORS])
    spec = ScenarioSpec(
        name=f"random-{seed}",
        description=f"Randomised scenario {seed}: {routine} routine, {len(lidars)} LiDARs "
        f"({', '.join(m.model.kind for m in lidars)}), {len(scene.objects)} objects, "
        f"{errors} initial errors",
        lidars=lidars,
        scene=scene,
        motion=motion,
        extrinsic_error=ranges.extrinsic_small if errors == "small" else ranges.extrinsic_large,
        odometry_error=PerturbationBounds(
            translation_m=_uniform(rng, ranges.odometry_translation_m),
            rotation_deg=_uniform(rng, ranges.odometry_rotation_deg),
        ),
        odometry_drift=PlanarDrift(
            translation_m=_uniform(rng, ranges.drift_translation_m),
            rotation_deg=_uniform(rng, ranges.drift_rotation_deg),
        ),
        world=WorldKind.OPEN_FLOOR,
        scenario_class=scenario_class(routine, sensors, errors),
    )
    offsets = _clock(spec, np.random.default_rng([seed, _CLOCK]), ranges)
    spec = spec.model_copy(update={"header_clock_offset_ns": offsets})
    if world is None:
        return spec
    if world == RANDOM_WORLD:
        world = WORLDS[int(np.random.default_rng([seed, _WORLD]).integers(len(WORLDS)))]
    return spec.model_copy(
        update={
            "description": f"{spec.description}; world: {world}",
            "scene": _world_scene(world, scene, motion, ranges),
            "world": _WORLD_KINDS[world],
            "scenario_class": scenario_class(routine, sensors, errors, world),
        }
    )


def world_name(spec: ScenarioSpec) -> str:
    """Which of `WORLDS` a spec's world is."""
    return next(name for name, kind in _WORLD_KINDS.items() if kind is spec.world)


def _world_scene(
    world: str, scene: SceneSpec, motion: RouteMotion, ranges: RandomRanges
) -> SceneSpec:
    """`scene` with the options `world` sets, sized so that the path stays clear of them."""
    options = _WORLD_OPTIONS[world]
    reach = scene.robot_band(motion.radius_band_m())[1]
    update: dict[str, object] = {}
    if "room" in options:
        room = ranges.room
        aisle = ranges.walkway_aisle_m if "walkers" in options else ranges.room_aisle_m
        low = max(
            room.wall_distance_m[0], reach + room.shelf_depth_m[1] + room.shelf_gap_m[1] + aisle
        )
        high = max(room.wall_distance_m[1], low + ranges.room_wall_spread_m)
        update["room"] = room.model_copy(update={"wall_distance_m": (low, high)})
    if "walkers" in options:
        walkers = ranges.walkers.model_copy(
            update={
                "kinds": (WalkerKind.PERSON, WalkerKind.CART)
                if world == "factory"
                else (WalkerKind.PERSON,)
            }
        )
        low, high = walkers.offset_m
        nearest = max(low, reach + _largest_walker_m(walkers) + _WALKWAY_MARGIN_M)
        update["walkers"] = walkers.model_copy(
            update={"offset_m": (nearest, max(high, nearest + high - low))}
        )
    if "floor" in options:
        update["floor"] = ranges.floor
    if "dust" in options:
        update["dust"] = ranges.dust
    return scene.model_copy(update=update)


def _largest_walker_m(spec: WalkersSpec) -> float:
    """The largest footprint radius a walker of `spec` can have."""
    (_, x), (_, y), _ = spec.cart_size_m
    cart = 0.5 * math.hypot(x, y) if WalkerKind.CART in spec.kinds else 0.0
    return max(spec.person_radius_m[1] if WalkerKind.PERSON in spec.kinds else 0.0, cart)


def _uniform(rng: np.random.Generator, bounds: Range) -> float:
    return float(rng.uniform(*bounds))


def _integer(rng: np.random.Generator, bounds: tuple[int, int]) -> int:
    return int(rng.integers(bounds[0], bounds[1] + 1))


def _routine(routine: str, rng: np.random.Generator, ranges: RandomRanges) -> RouteMotion:
    speeds = Speeds(
        drive_mps=_uniform(rng, ranges.drive_mps), turn_dps=_uniform(rng, ranges.turn_dps)
    )
    low, high = sorted(rng.uniform(*ranges.dwell_s, size=2))
    spacing = _uniform(rng, ranges.stop_spacing_m)

    def dwells(count: int) -> list[float]:
        return [float(x) for x in rng.uniform(low, high, size=count)]

    if routine == "rotate":
        step = _uniform(rng, ranges.rotate_step_deg) * (1 if rng.random() < 0.5 else -1)
        return rotate_in_place(step, dwells(_integer(rng, ranges.rotate_stops)), speeds)
    if routine == "loop":
        first = _uniform(rng, ranges.loop_side_m)
        sides = (first, first if rng.random() < 0.5 else _uniform(rng, ranges.loop_side_m))
        left = bool(rng.random() < 0.5)
        return loop(sides, spacing, dwells(loop_stop_count(sides, spacing)), speeds, left=left)
    if routine == "figure-eight":
        radius = _uniform(rng, ranges.figure_eight_radius_m)
        per_circle = max(4, math.ceil(2.0 * math.pi * radius / spacing - 1e-9))
        return figure_eight(radius, per_circle, dwells(2 * per_circle + 1), speeds)
    length = _uniform(rng, ranges.lane_length_m)
    return lane(length, spacing, dwells(lane_stop_count(length, spacing)), speeds)


def _model(name: str, rng: np.random.Generator, ranges: RandomRanges) -> LidarModel:
    if name == "mid70":
        return Mid70()
    if name == "mid360":
        return Mid360(line_field=bool(rng.random() < 0.5))
    beams = int(name.removeprefix("spinning"))
    elevation, resolution = {16: ((-15.0, 15.0), 0.2), 32: ((-25.0, 15.0), 0.2)}.get(
        beams, ((-22.5, 22.5), 0.35)
    )
    width = _uniform(rng, ranges.spinning_azimuth_deg)
    return SpinningLidar(
        beams=beams,
        elevation_deg=elevation,
        azimuth_resolution_deg=resolution,
        azimuth_mask_deg=(-width / 2.0, width / 2.0),
        beam_field=BEAM_FIELDS[int(rng.integers(len(BEAM_FIELDS)))],
    )


_ROSETTES = ("mid70", "mid360")
_SPINNING = ("spinning16", "spinning32", "spinning64")


def _lidars(sensors: str, rng: np.random.Generator, ranges: RandomRanges) -> tuple[LidarMount, ...]:
    count = _integer(rng, ranges.lidar_count)
    pool = {"rosette": _ROSETTES, "spinning": _SPINNING}.get(sensors, _ROSETTES + _SPINNING)
    names = [str(rng.choice(pool)) for _ in range(count)]
    if sensors == "mixed" and not (set(names) & set(_ROSETTES) and set(names) & set(_SPINNING)):
        # One of each family: the last LiDAR comes from the family the others lack.
        names[-1] = str(rng.choice(_SPINNING if set(names) <= set(_ROSETTES) else _ROSETTES))
    yaws = _spread_yaws(rng, count, ranges)
    mounts = []
    for index, (name, yaw) in enumerate(zip(names, yaws, strict=True)):
        model = _model(name, rng, ranges)
        roll = _uniform(rng, ranges.mount_roll_deg) + (180.0 if name == "mid360" else 0.0)
        tilt = _uniform(rng, ranges.mount_tilt_deg)
        height = _uniform(rng, ranges.mount_height_m)
        mounts.append(
            LidarMount(
                frame=f"lidar_{index}",
                model=model,
                xyz=(*_on_chassis(yaw), height),
                rpy_deg=(roll, tilt, yaw),
            )
        )
    return tuple(mounts)


def _spread_yaws(rng: np.random.Generator, count: int, ranges: RandomRanges) -> list[float]:
    """`count` yaws, each pair at least `min_yaw_separation_deg` apart round the circle."""
    for _ in range(_PLACEMENT_TRIES):
        yaws = [_uniform(rng, ranges.mount_yaw_deg) for _ in range(count)]
        gaps = [
            abs((a - b + 180.0) % 360.0 - 180.0) for i, a in enumerate(yaws) for b in yaws[i + 1 :]
        ]
        if min(gaps) >= ranges.min_yaw_separation_deg:
            return yaws
    raise ConfigError(
        f"could not spread {count} mount yaws {ranges.min_yaw_separation_deg} deg apart; "
        "lower min_yaw_separation_deg or the LiDAR count"
    )


def _on_chassis(yaw_deg: float, half_size: Sequence[float] = (0.35, 0.25)) -> tuple[float, float]:
    """Where the chassis outline (a rectangle, the robot's footprint) meets the ray at yaw."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    scale = min(half_size[0] / max(abs(c), 1e-9), half_size[1] / max(abs(s), 1e-9))
    return scale * c, scale * s


def _objects(
    motion: RouteMotion, rng: np.random.Generator, ranges: RandomRanges
) -> tuple[PlacedObject, ...]:
    path = motion.path_xy(step_m=0.05)
    robot_radius = 0.5 * math.hypot(*SceneSpec().robot_size_m[:2])
    placed: list[PlacedObject] = []
    radii: list[float] = []
    for _ in range(_integer(rng, ranges.object_count)):
        for _ in range(_PLACEMENT_TRIES):
            obj, r_xy = _draw_object(rng, ranges)
            anchor = path[int(rng.integers(len(path)))]
            angle = rng.uniform(-math.pi, math.pi)
            xy = anchor + _uniform(rng, ranges.object_distance_m) * np.array(
                [math.cos(angle), math.sin(angle)]
            )
            nearest = float(np.min(np.linalg.norm(path - xy, axis=1)))
            clear = max(ranges.object_distance_m[0], robot_radius + ranges.robot_clearance_m + r_xy)
            if nearest < clear or any(
                math.dist(xy, other.xy) < r_xy + r_other + ranges.object_gap_m
                for other, r_other in zip(placed, radii, strict=True)
            ):
                continue
            placed.append(obj.model_copy(update={"xy": (float(xy[0]), float(xy[1]))}))
            radii.append(r_xy)
            break
        else:
            raise ConfigError(
                f"could not place object {len(placed) + 1} near the path without touching the "
                "robot or another object; lower object_count or widen object_distance_m"
            )
    return tuple(placed)


def _draw_object(rng: np.random.Generator, ranges: RandomRanges) -> tuple[PlacedObject, float]:
    """An object of a random kind, size and yaw at the origin, and its footprint's radius."""
    kind = list(ObjectKind)[int(rng.integers(len(ObjectKind)))]
    height = _uniform(rng, ranges.object_height_m)
    dimensions: dict[str, float]
    if kind is ObjectKind.BOX:
        x, y = (_uniform(rng, ranges.box_side_m) for _ in range(2))
        dimensions, r_xy = {"x": x, "y": y, "z": height}, 0.5 * math.hypot(x, y)
    elif kind is ObjectKind.CYLINDER:
        radius = _uniform(rng, ranges.cylinder_radius_m)
        dimensions, r_xy = {"radius": radius, "height": height}, radius
    else:
        length = _uniform(rng, ranges.capsule_length_m)
        dimensions, r_xy = {"radius": height / 2.0, "length": length}, length / 2 + height / 2
    obj = PlacedObject(
        kind=kind,
        dimensions=dimensions,
        xy=(0.0, 0.0),
        yaw_deg=_uniform(rng, (-180.0, 180.0)),
        reflectivity=_uniform(rng, ranges.reflectivity),
    )
    return obj, r_xy


def _clock(spec: ScenarioSpec, rng: np.random.Generator, ranges: RandomRanges) -> dict[str, int]:
    """Header clock offsets per topic: none, all on simulated time, or some LiDARs' clocks off."""
    clock = CLOCKS[int(rng.integers(len(CLOCKS)))]
    topics = [mount.topic for mount in spec.lidars]
    if clock == "simulated":
        start_ns = round(_uniform(rng, ranges.simulated_start_s) * 1e9)
        offset = start_ns - spec.start_time_ns
        return {topic: offset for topic in [*topics, "/odom"]}
    if clock == "lidar-offset":
        chosen = rng.permutation(len(topics))[: _integer(rng, (1, len(topics)))]
        return {
            topics[i]: round(_uniform(rng, ranges.lidar_clock_offset_days) * _DAY_NS)
            for i in sorted(chosen.tolist())
        }
    return {}


def clock_kind(spec: ScenarioSpec) -> str:
    """Which of `CLOCKS` a spec's header clocks follow."""
    offsets = spec.header_clock_offset_ns
    if not offsets:
        return "synced"
    return "simulated" if "/odom" in offsets else "lidar-offset"
