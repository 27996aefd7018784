"""The registry of synthetic scenarios: robot, LiDAR mounts, world and motion as frozen specs.

`set1-*` and `set2-*` follow the paper's simulation protocol (two or four Livox Mid-70 with
non-overlapping fields of view, tilted about 35 deg down, 16 stops rotating in place, objects
0.25 m tall). Mount heights follow the paper's robot (base 0.54 m above the floor, LiDARs
0.28-0.34 m above it); `base_link` itself lies on the floor, like REP 105's `base_footprint`.
"""

from __future__ import annotations

import enum
from functools import cache

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from pipeline.errors import ConfigError
from pipeline.synth.lidar_models import LidarModel, Mid70, SpinningLidar
from pipeline.synth.motion import ArcMotion, Motion
from pipeline.synth.perturbation import PerturbationBounds, PlanarDrift
from pipeline.synth.scene import ObjectKind, Ring, SceneSpec
from pipeline.synth.world_scenarios import world_scenarios
from pipeline.transforms import Matrix4, from_xyz_rpy

_FROZEN = ConfigDict(frozen=True, extra="forbid")


class MountFrame(BaseModel):
    """An intermediate tf frame between the base and a LiDAR (a bracket), `T_base_mount`."""

    model_config = _FROZEN

    frame: str
    xyz: tuple[float, float, float]
    rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def T_base_mount(self) -> Matrix4:
        return from_xyz_rpy(self.xyz, np.radians(self.rpy_deg))


class LidarMount(BaseModel):
    """Where a LiDAR truly sits on the base: `xyz` (m) and fixed-axis roll, pitch, yaw (deg).

    With `via`, `/tf_static` publishes the chain `base -> via.frame -> frame` instead of one edge.
    """

    model_config = _FROZEN

    frame: str
    model: LidarModel
    xyz: tuple[float, float, float]
    rpy_deg: tuple[float, float, float]
    via: MountFrame | None = None

    @property
    def topic(self) -> str:
        return f"/{self.frame}/points"

    def T_base_lidar(self) -> Matrix4:
        return from_xyz_rpy(self.xyz, np.radians(self.rpy_deg))


class WorldKind(enum.StrEnum):
    """The world round the robot: the open floor, or the options of a randomised world (the
    scene's room, walkers, floor and dust)."""

    OPEN_FLOOR = "open-floor"
    ROOM = "room"
    PEOPLE = "people"
    UNEVEN_FLOOR = "uneven-floor"
    DUST = "dust"
    FACTORY = "factory"


class ScenarioSpec(BaseModel):
    """Everything that defines a synthetic recording except the seed."""

    model_config = _FROZEN

    name: str
    description: str
    lidars: tuple[LidarMount, ...]
    scene: SceneSpec = SceneSpec()
    motion: Motion = ArcMotion()
    extrinsic_error: PerturbationBounds = PerturbationBounds(translation_m=0.2, rotation_deg=5.0)
    odometry_error: PerturbationBounds = PerturbationBounds(translation_m=0.2, rotation_deg=3.0)
    odometry_drift: PlanarDrift = Field(
        default=PlanarDrift(),
        description="error growing along the path, on top of the per-stop one",
    )
    header_clock_offset_ns: dict[str, int] = Field(
        default_factory=dict,
        description="per topic: header stamps = bag log time + offset (simulated time, a LiDAR "
        "whose clock is off); topics not named have none",
    )
    world: WorldKind = WorldKind.OPEN_FLOOR
    scenario_class: str = Field(
        default="", description="benchmark class, e.g. routine/sensors/errors of a random draw"
    )
    rate_scale: float = Field(default=1.0, gt=0, description="multiplies every LiDAR's point rate")
    odometry_hz: float = Field(default=50.0, gt=0)
    base_frame: str = "base_link"
    odom_frame: str = "odom"
    start_time_ns: int = Field(
        default=1_700_000_000 * 10**9, ge=0, description="ROS time of the first stop"
    )

    @model_validator(mode="after")
    def _check(self) -> ScenarioSpec:
        frames = [lidar.frame for lidar in self.lidars]
        if len(frames) < 2 or len(set(frames)) != len(frames):
            raise ValueError(
                f"a scenario needs two or more LiDARs with distinct frames; got {frames}"
            )
        return self

    @property
    def reference_frame(self) -> str:
        """The input contract's default: the first LiDAR frame in sorted order."""
        return min(lidar.frame for lidar in self.lidars)


def _front_and_rear(
    model: LidarModel,
    pitch_deg: tuple[float, float] = (35.4, 34.4),
    height_m: tuple[float, float] = (0.88, 0.82),
    rear_via: MountFrame | None = None,
) -> tuple[LidarMount, LidarMount]:
    """The paper's two-LiDAR layout: one looking forward, one backward, both tilted down."""
    return (
        LidarMount(
            frame="lidar_front",
            model=model,
            xyz=(0.30, 0.0, height_m[0]),
            rpy_deg=(0, pitch_deg[0], 0),
        ),
        LidarMount(
            frame="lidar_rear",
            model=model,
            xyz=(-0.30, 0.0, height_m[1]),
            rpy_deg=(0, pitch_deg[1], 180),
            via=rear_via,
        ),
    )


def _set1(kinds: tuple[ObjectKind, ...], name: str, description: str) -> ScenarioSpec:
    return ScenarioSpec(
        name=name,
        description=description,
        lidars=_front_and_rear(Mid70()),
        scene=SceneSpec(object_kinds=kinds),
    )


def _set2(kinds: tuple[ObjectKind, ...], name: str) -> ScenarioSpec:
    # 30 deg of tilt keeps the four 70.4 deg cones apart (their axes are 75.5 deg apart).
    mid70 = Mid70()
    side = MountFrame(frame="mount_side", xyz=(0.0, 0.0, 0.60))
    return ScenarioSpec(
        name=name,
        description=f"Paper set 2: four Mid-70 (front, left, rear, right), {kinds[0].value} "
        "objects; the side LiDARs hang from a mount frame (tf chain base_link -> mount_side -> "
        "lidar)",
        lidars=(
            LidarMount(frame="lidar_front", model=mid70, xyz=(0.35, 0.0, 0.88), rpy_deg=(0, 30, 0)),
            LidarMount(
                frame="lidar_left",
                model=mid70,
                xyz=(0.0, 0.25, 0.85),
                rpy_deg=(0, 30, 90),
                via=side,
            ),
            LidarMount(
                frame="lidar_rear", model=mid70, xyz=(-0.35, 0.0, 0.82), rpy_deg=(0, 30, 180)
            ),
            LidarMount(
                frame="lidar_right",
                model=mid70,
                xyz=(0.0, -0.25, 0.85),
                rpy_deg=(0, 30, -90),
                via=side,
            ),
        ),
        scene=SceneSpec(
            object_kinds=kinds, rings=(Ring(r_min_m=1.0, r_max_m=2.6, count=(12, 16)),)
        ),
    )


_KINDS = (ObjectKind.BOX, ObjectKind.CYLINDER, ObjectKind.CAPSULE)


@cache
def _registry() -> dict[str, ScenarioSpec]:
    specs = [
        *(
            _set1(
                (kind,),
                f"set1-{kind.value}",
                f"Paper set 1: two Mid-70 tilted ~35 deg down, front and "
                f"rear, {kind.value} objects, 16 stops rotating in place",
            )
            for kind in _KINDS
        ),
        *(_set2((kind,), f"set2-{kind.value}") for kind in _KINDS),
        _floor_only(),
        _spinning(),
        _driven(),
        *world_scenarios(_set1(_KINDS, "set1-mixed", "")),
        _tiny(),
    ]
    return {spec.name: spec for spec in specs}


def _floor_only() -> ScenarioSpec:
    floor_only = _set1(
        _KINDS,
        "floor-only",
        "Set 1 LiDARs on a bare floor: the floor fixes only roll, "
        "pitch and height, so x, y and yaw are undeterminable",
    )
    return floor_only.model_copy(update={"scene": SceneSpec(rings=())})


def _spinning() -> ScenarioSpec:
    spinning = SpinningLidar(azimuth_mask_deg=(-70.0, 70.0))
    return ScenarioSpec(
        name="spinning",
        description="Two 16-beam spinning LiDARs tilted 20 deg down, front and rear, azimuth "
        "masks of +-70 deg so their fields of view do not overlap; mixed objects",
        lidars=_front_and_rear(spinning, pitch_deg=(20, 20), height_m=(0.9, 0.9)),
        scene=SceneSpec(object_kinds=_KINDS),
    )


def _driven() -> ScenarioSpec:
    return _set1(_KINDS, "driven", "").model_copy(
        update={
            "description": "Set 1 LiDARs driving a loop of radius 2.5 m with 12 stops, mixed "
            "objects inside and outside the loop; the rear LiDAR hangs from a mount frame",
            "lidars": _front_and_rear(
                Mid70(), rear_via=MountFrame(frame="mount_rear", xyz=(-0.25, 0.0, 0.6))
            ),
            "motion": ArcMotion(stops=12, radius_m=2.5, step_deg=30.0, dwell_s=1.5, move_s=2.5),
            "scene": SceneSpec(
                object_kinds=_KINDS,
                rings=(
                    Ring(r_min_m=0.3, r_max_m=1.7, count=(6, 8)),
                    Ring(r_min_m=3.3, r_max_m=3.9, count=(16, 20)),
                ),
            ),
        }
    )


def _tiny() -> ScenarioSpec:
    return ScenarioSpec(
        name="tiny",
        description="For unit tests: two Mid-70 at 5 % of their rate, 4 stops, boxes; the rear "
        "LiDAR hangs from a mount frame",
        lidars=_front_and_rear(
            Mid70(max_range_m=12.0),
            rear_via=MountFrame(frame="mount_rear", xyz=(-0.25, 0.0, 0.6), rpy_deg=(0, 0, 180)),
        ),
        scene=SceneSpec(
            rings=(Ring(r_min_m=1.0, r_max_m=2.4, count=(6, 8)),), floor_half_size_m=6.0
        ),
        motion=ArcMotion(stops=4, step_deg=90.0, dwell_s=1.3, move_s=0.5),
        rate_scale=0.05,
    )


def scenario_names() -> tuple[str, ...]:
    return tuple(sorted(_registry()))


def get_scenario(name: str) -> ScenarioSpec:
    """The registered scenario called `name`."""
    try:
        return _registry()[name]
    except KeyError:
        raise ConfigError(
            f"unknown scenario {name!r}; choose one of: {', '.join(scenario_names())} (or a "
            "randomised one: `fleetcal synth random --seed N`, random_scenario(seed) in Python)"
        ) from None
