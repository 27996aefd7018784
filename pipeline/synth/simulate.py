"""Simulated LiDAR scans with noise labels, and whole calibration problems built in memory.

`scan` casts one LiDAR's rays into a scene. `World` fixes everything a seed decides (objects, the
room, walkers and floor where the scenario has them, true and perturbed extrinsics, odometry
errors) and simulates any scan of a recording on demand,
each with its own random stream, so a scan's points do not depend on which other scans were
simulated: `simulate_problem` (stops only, in memory) and `write_recording` (every scan, to a
bag) produce the same stop clouds.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError
from pipeline.problem import CalibrationProblem, LidarInfo, RecordingInfo, Stop
from pipeline.synth.bleeding import BleedingModel
from pipeline.synth.bleeding_cast import cast_with_beam
from pipeline.synth.dust import DustSpec, draw_dust
from pipeline.synth.floor import draw_floor
from pipeline.synth.lidar_models import Firing, LidarModel
from pipeline.synth.motion import interpolate_drift
from pipeline.synth.perturbation import drift_errors, random_perturbation
from pipeline.synth.raycast import Returns, cast_with_footprint
from pipeline.synth.room import Room, build_room
from pipeline.synth.scenarios import ScenarioSpec, get_scenario
from pipeline.synth.scene import NOT_STATIC, Scene, build_scene, place_objects
from pipeline.synth.truth import LidarTruth, ScanLabels, StopTruth, Truth
from pipeline.synth.walkers import Walker, draw_walkers
from pipeline.transforms import Matrix4

PoseFn = Callable[[NDArray[np.float64]], NDArray[np.float64]]
"""Times (K,) -> `T_world_lidar` (K, 4, 4): the sensor's pose while it scans."""

_NS = 1_000_000_000
_MAX_INTENSITY = 255.0
# Stream ids that keep the random draws of one concern independent of the others.
_SCENE, _SCAN, _EXTRINSICS, _ODOMETRY, _DRIFT = 0, 1, 2, 3, 4
_ROOM, _WALKERS, _FLOOR = 5, 6, 7


@dataclass(frozen=True)
class LabelledScan:
    """One scan. `points` (N, 3) float64 in the LiDAR frame *at each point's firing time* (no
    motion compensation, as drivers publish them); `times` (N,) seconds since the recording
    started; `intensity` (N,) float32; `is_bleeding` (N,) bool; `object_index` (N,) int16
    (index into the scene's objects, -1 the floor, -2 a walker or dust); `is_moving` (N,) bool
    (on a walker); `is_spurious` (N,) bool (dust)."""

    stamp_ns: int
    points: NDArray[np.float64]
    times: NDArray[np.float64]
    intensity: NDArray[np.float32]
    is_bleeding: NDArray[np.bool_]
    object_index: NDArray[np.int16]
    is_moving: NDArray[np.bool_]
    is_spurious: NDArray[np.bool_]

    def __len__(self) -> int:
        return len(self.points)


def scan(
    scene: Scene,
    lidar: LidarModel,
    T_world_lidar: Matrix4 | PoseFn,
    t0: float,
    duration: float,
    rng: np.random.Generator,
    *,
    rate_scale: float = 1.0,
    slice_s: float = 0.01,
    stamp_ns: int = 0,
    dust: DustSpec | None = None,
    bleeding: BleedingModel | None = None,
) -> LabelledScan:
    """Cast `lidar`'s rays fired in `[t0, t0 + duration)` (seconds since the recording started).

    `T_world_lidar` is a fixed pose, or a function of time for a moving sensor: then the scan is
    cast in slices of `slice_s`, each from the pose at its middle. Rays that hit nothing within
    the model's range give no point. Range noise is Gaussian with the model's sigma; bleeding
    points come from `raycast.cast_with_footprint` (the model's `footprint_deg`), or with
    `bleeding` from that beam model (`bleeding_cast.cast_with_beam`), labelled when they float
    more than three sigmas away from both surfaces they mix. With `dust`, a few rays return from
    dust near the sensor instead (drawn from `rng` after everything else, so the other rays keep
    their noise).
    """
    firing = lidar.firing(t0, duration, rate_scale)
    rays = _world_rays(firing, T_world_lidar, t0, slice_s)
    returns = _returns(scene, lidar, rays, rng, bleeding)
    range_m, geom = returns.range_m, returns.geom
    keep = np.isfinite(range_m) & (range_m >= lidar.min_range_m)
    measured = np.full(len(range_m), np.inf)
    measured[keep] = range_m[keep] + rng.normal(0.0, lidar.range_noise_m, size=int(keep.sum()))
    reflectivity = np.where(keep, scene.geom_reflectivity[geom], 0.0)
    cos_incidence = returns.cos_incidence
    object_index = scene.geom_object[geom].astype(np.int16)
    is_spurious = np.zeros(len(range_m), dtype=bool)
    if dust is not None:
        specks = draw_dust(dust, rng, np.where(keep, range_m, np.inf), lidar.min_range_m)
        is_spurious = specks.is_dust
        measured = np.where(is_spurious, specks.range_m, measured)
        reflectivity = np.where(is_spurious, specks.reflectivity, reflectivity)
        cos_incidence = np.where(is_spurious, 1.0, cos_incidence)
        object_index = np.where(is_spurious, NOT_STATIC, object_index).astype(np.int16)
        keep = keep | is_spurious
    intensity = np.clip(
        _MAX_INTENSITY * reflectivity[keep] * cos_incidence[keep], 0.0, _MAX_INTENSITY
    )
    is_moving = (scene.geom_walker[geom] >= 0) & ~is_spurious
    return LabelledScan(
        stamp_ns=stamp_ns,
        points=firing.directions[keep] * measured[keep, None],
        times=firing.times[keep],
        intensity=intensity.astype(np.float32),
        is_bleeding=returns.is_bleeding[keep] & ~is_spurious[keep],
        object_index=object_index[keep],
        is_moving=is_moving[keep],
        is_spurious=is_spurious[keep],
    )


@dataclass(frozen=True)
class _WorldRays:
    """Rays of one scan in the world frame: per ray `origins`, `directions` and the sensor's
    z axis `up` ((N, 3) each, or (3,) for a scan cast from one pose)."""

    origins: NDArray[np.float64]
    directions: NDArray[np.float64]
    up: NDArray[np.float64]


def _world_rays(
    firing: Firing, T_world_lidar: Matrix4 | PoseFn, t0: float, slice_s: float
) -> _WorldRays:
    """Each ray cast from its slice's pose (one pose for a fixed `T_world_lidar`)."""
    starts: NDArray[np.int64] = np.zeros(1, dtype=np.int64)
    ends: NDArray[np.int64] = np.full(1, len(firing), dtype=np.int64)
    if not callable(T_world_lidar):
        poses = np.asarray(T_world_lidar, dtype=np.float64)[None]
    elif len(firing):
        slice_index = np.floor((firing.times - t0) / slice_s).astype(np.int64)
        bounds = np.flatnonzero(np.diff(slice_index)) + 1
        starts = np.concatenate([starts, bounds])
        ends = np.concatenate([bounds, ends])
        middles = t0 + (slice_index[starts] + 0.5) * slice_s
        poses = T_world_lidar(middles.astype(np.float64))
    else:
        poses = T_world_lidar(np.array([t0]))
    if len(poses) == 1:
        return _WorldRays(poses[0, :3, 3], firing.directions @ poses[0, :3, :3].T, poses[0, :3, 2])
    slice_of_ray = np.repeat(np.arange(len(poses)), ends - starts)
    rotations = poses[slice_of_ray, :3, :3]
    return _WorldRays(
        poses[slice_of_ray, :3, 3],
        np.einsum("nij,nj->ni", rotations, firing.directions),
        rotations[:, :, 2],
    )


def _returns(
    scene: Scene,
    lidar: LidarModel,
    rays: _WorldRays,
    rng: np.random.Generator,
    bleeding: BleedingModel | None,
) -> Returns:
    """What the receiver reports per ray: the model's own footprint, or `bleeding`'s beam."""
    margin = 3.0 * lidar.range_noise_m
    if bleeding is None:
        return cast_with_footprint(
            scene,
            rays.origins,
            rays.directions,
            max_range=lidar.max_range_m,
            footprint_deg=lidar.footprint_deg,
            label_margin_m=margin,
            rng=rng,
        )
    return cast_with_beam(
        scene,
        rays.origins,
        rays.directions,
        rays.up,
        model=bleeding,
        max_range=lidar.max_range_m,
        label_margin_m=margin,
        rng=rng,
    )


@dataclass(frozen=True, eq=False)
class World:
    """A scenario made concrete by a seed: the scene, true and perturbed poses, odometry errors.

    Times: `t` in seconds since the first stop began (the recording's start); ROS time is
    `spec.start_time_ns + t`. `bleeding`: the beam model every LiDAR's mixed returns come from;
    None: each LiDAR model's own footprint (how every scenario renders by default).
    """

    spec: ScenarioSpec
    seed: int
    rate_scale: float
    scene: Scene
    T_base_lidar_true: tuple[Matrix4, ...]
    T_base_lidar_initial: tuple[Matrix4, ...]
    odometry_errors: NDArray[np.float64]
    bleeding: BleedingModel | None = None

    @property
    def duration_s(self) -> float:
        return self.spec.motion.duration_s

    def scan_period_ns(self, lidar_index: int) -> int:
        return round(self.spec.lidars[lidar_index].model.scan_period_s * _NS)

    def scan_count(self, lidar_index: int) -> int:
        """Scans of this LiDAR in the recording (the last one ends by the last stop's end)."""
        return int(round(self.duration_s * _NS) // self.scan_period_ns(lidar_index))

    def stop_scans(self, lidar_index: int, stop_index: int) -> range:
        """Indices of the scans lying wholly inside the stop."""
        period = self.scan_period_ns(lidar_index)
        start, end = (round(t * _NS) for t in self.spec.motion.stop_intervals()[stop_index])
        return range(-(-start // period), end // period)

    def is_still(self, lidar_index: int, scan_index: int) -> bool:
        period = self.scan_period_ns(lidar_index)
        start, end = scan_index * period, (scan_index + 1) * period
        return any(
            round(a * _NS) <= start and end <= round(b * _NS)
            for a, b in self.spec.motion.stop_intervals()
        )

    def T_world_base(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        """True `T_world_base` (K, 4, 4) at times `t` (K,): the planned planar pose, resting on
        the floor (its height, roll and pitch follow the floor under the wheels)."""
        planar = self.spec.motion.poses(t)
        if self.scene.floor is None:
            return planar
        size = self.spec.scene.robot_size_m
        return self.scene.floor.rest(planar, (size[0], size[1]))

    def T_world_lidar(self, lidar_index: int) -> PoseFn:
        T_base_lidar = self.T_base_lidar_true[lidar_index]
        return lambda t: self.T_world_base(t) @ T_base_lidar

    def odometry(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        """Odometry's `T_odom_base` (K, 4, 4): the planar pose times the drifting error. Wheel
        odometry integrates the wheels' travel in the plane; it never sees the floor's tilt."""
        return self.spec.motion.poses(t) @ interpolate_drift(
            self.spec.motion, self.odometry_errors, t
        )

    def simulate_scan(self, lidar_index: int, scan_index: int) -> LabelledScan:
        """Scan `scan_index` of LiDAR `lidar_index`, the same whichever scans came before."""
        mount = self.spec.lidars[lidar_index]
        period = self.scan_period_ns(lidar_index)
        t0 = scan_index * period / _NS
        rng = np.random.default_rng([self.seed, _SCAN, lidar_index, scan_index])
        pose_fn = self.T_world_lidar(lidar_index)
        pose: Matrix4 | PoseFn = pose_fn
        if self.is_still(lidar_index, scan_index):
            pose = pose_fn(np.array([t0]))[0]
        middle = t0 + period / (2 * _NS)
        self.scene.place_robot(self.T_world_base(np.array([middle]))[0])
        self.scene.place_walkers(middle)
        return scan(
            self.scene,
            mount.model,
            pose,
            t0,
            period / _NS,
            rng,
            rate_scale=self.rate_scale,
            stamp_ns=self.spec.start_time_ns + scan_index * period,
            dust=self.spec.scene.dust,
            bleeding=self.bleeding,
        )

    def simulate_stop(self, lidar_index: int, stop_index: int) -> list[LabelledScan]:
        """The scans of LiDAR `lidar_index` that a stop's cloud accumulates (`stop_scans`)."""
        return [
            self.simulate_scan(lidar_index, k) for k in self.stop_scans(lidar_index, stop_index)
        ]

    @cached_property
    def stop_times(self) -> NDArray[np.float64]:
        """(stops, 2) start and end of each stop, seconds since the recording started."""
        return self.spec.motion.stop_intervals()

    def truth(self, labels: dict[str, ScanLabels] | None = None) -> Truth:
        start_s = self.spec.start_time_ns / _NS
        stop_true = self.T_world_base(self.stop_times[:, 0])
        stop_initial = self.odometry(self.stop_times[:, 0])
        return Truth(
            scenario=self.spec.name,
            seed=self.seed,
            rate_scale=self.rate_scale,
            base_frame=self.spec.base_frame,
            odom_frame=self.spec.odom_frame,
            reference_frame=self.spec.reference_frame,
            lidars=tuple(
                LidarTruth(
                    frame=mount.frame,
                    topic=mount.topic,
                    model=mount.model.kind,
                    optical_axis=mount.model.optical_axis,
                    scan_period_s=self.scan_period_ns(i) / _NS,
                    T_base_lidar_true=self.T_base_lidar_true[i],
                    T_base_lidar_initial=self.T_base_lidar_initial[i],
                )
                for i, mount in enumerate(self.spec.lidars)
            ),
            stops=tuple(
                StopTruth(
                    index=j,
                    t_start=start_s + float(a),
                    t_end=start_s + float(b),
                    T_odom_base_true=stop_true[j],
                    T_odom_base_initial=stop_initial[j],
                )
                for j, (a, b) in enumerate(self.stop_times)
            ),
            objects=self.scene.objects,
            labels=labels or {},
            scenario_class=self.spec.scenario_class,
            spec=self.spec.model_dump(mode="json"),
            floor=self.scene.floor,
            walkers=self.scene.walkers,
        )


def make_world(
    scenario: str | ScenarioSpec,
    seed: int,
    rate_scale: float = 1.0,
    *,
    bleeding: BleedingModel | None = None,
) -> World:
    """Fix everything `seed` decides for `scenario` (a registered name or a spec); `bleeding`
    replaces the LiDAR models' own footprints (`World.bleeding`)."""
    spec = get_scenario(scenario) if isinstance(scenario, str) else scenario
    if not (math.isfinite(rate_scale) and rate_scale > 0):
        raise ConfigError(
            f"rate_scale must be a positive number, got {rate_scale}; e.g. 0.1 keeps a tenth "
            "of every LiDAR's points"
        )
    motion = spec.motion
    true = tuple(mount.T_base_lidar() for mount in spec.lidars)
    scene = _build_world_scene(
        spec, seed, dict(zip((m.frame for m in spec.lidars), true, strict=True))
    )
    rng = np.random.default_rng([seed, _EXTRINSICS])
    initial = tuple(T @ random_perturbation(rng, spec.extrinsic_error) for T in true)
    rng = np.random.default_rng([seed, _ODOMETRY])
    errors = np.stack([random_perturbation(rng, spec.odometry_error) for _ in range(motion.stops)])
    travel = motion.travel_m(half_track_m=spec.scene.robot_size_m[1] / 2.0)
    fractions = travel / travel[-1] if travel[-1] > 0 else np.zeros_like(travel)
    drift = drift_errors(np.random.default_rng([seed, _DRIFT]), spec.odometry_drift, fractions)
    errors = drift @ errors
    return World(
        spec=spec,
        seed=seed,
        rate_scale=spec.rate_scale * rate_scale,
        scene=scene,
        T_base_lidar_true=true,
        T_base_lidar_initial=initial,
        odometry_errors=errors,
        bleeding=bleeding,
    )


def _build_world_scene(
    spec: ScenarioSpec, seed: int, mounts: dict[str, NDArray[np.float64]]
) -> Scene:
    """The scene `seed` draws: the room, the floor and the walkers (each from its own random
    stream, so an option left unset changes nothing else), then the objects clear of them."""
    scene_spec, motion = spec.scene, spec.motion
    keep_out = motion.radius_band_m()
    band = scene_spec.robot_band(keep_out)
    room = floor = None
    walkers: tuple[Walker, ...] = ()
    if scene_spec.room is not None:
        room = build_room(scene_spec.room, np.random.default_rng([seed, _ROOM]), band)
    if scene_spec.floor is not None:
        floor = draw_floor(
            scene_spec.floor, np.random.default_rng([seed, _FLOOR]), scene_spec.floor_half_size_m
        )
    if scene_spec.walkers is not None:
        walkers = draw_walkers(
            scene_spec.walkers, np.random.default_rng([seed, _WALKERS]), band, room
        )
    objects = place_objects(
        scene_spec, np.random.default_rng([seed, _SCENE]), keep_out, _free_of(room, walkers)
    )
    objects += room.structures if room is not None else ()
    if floor is not None:
        objects = tuple(floor.stand(obj) for obj in objects)
    return build_scene(scene_spec, objects, mounts, floor=floor, walkers=walkers)


def _free_of(
    room: Room | None, walkers: tuple[Walker, ...]
) -> Callable[[NDArray[np.float64], float], bool] | None:
    """Whether a footprint circle keeps clear of the room's structures and the walkers' ways."""
    if room is None and not walkers:
        return None

    def free(xy: NDArray[np.float64], radius: float) -> bool:
        return (room is None or room.gap(xy, radius) >= 0) and all(
            walker.path_gap(xy, radius) >= 0 for walker in walkers
        )

    return free


def simulate_problem(
    scenario: str | ScenarioSpec,
    seed: int = 0,
    rate_scale: float = 1.0,
    *,
    bleeding: BleedingModel | None = None,
) -> tuple[CalibrationProblem, Truth]:
    """The `CalibrationProblem` a reader would build from the scenario's recording, and its truth.

    Only the scans wholly inside each stop are simulated (those are all a stop cloud holds), so
    this is much faster than writing the bag. Stop poses are the odometry's (perturbed), LiDAR
    extrinsics the perturbed `/tf_static` ones. `truth.stop_labels(j, frame)` lines up with
    `problem.stops[j].clouds[frame]`. `bleeding`: as for `make_world`.
    """
    world = make_world(scenario, seed, rate_scale, bleeding=bleeding)
    spec = world.spec
    start_s = spec.start_time_ns / _NS
    odometry = world.odometry(world.stop_times[:, 0])
    chunks: dict[str, list[LabelledScan]] = {m.frame: [] for m in spec.lidars}
    stops = []
    for j, (a, b) in enumerate(world.stop_times):
        clouds, counts, sizes = {}, {}, {}
        for i, mount in enumerate(spec.lidars):
            scans = world.simulate_stop(i, j)
            chunks[mount.frame] += scans
            clouds[mount.frame] = (
                np.concatenate([s.points for s in scans]) if scans else np.zeros((0, 3))
            )
            counts[mount.frame] = len(scans)
            sizes[mount.frame] = tuple(len(s.points) for s in scans)
        stops.append(
            Stop(
                index=j,
                t_start=start_s + float(a),
                t_end=start_s + float(b),
                T_odom_base=odometry[j],
                clouds=clouds,
                scan_counts=counts,
                scan_sizes=sizes,
            )
        )
    problem = CalibrationProblem(
        lidars=_lidar_infos(world),
        stops=tuple(stops),
        base_frame=spec.base_frame,
        odom_frame=spec.odom_frame,
        recording=RecordingInfo(
            path=f"synthetic:{spec.name}:{seed}",
            format="synthetic",
            t_start=start_s,
            t_end=start_s + world.duration_s,
        ),
    )
    labels = {frame: labels_of(chunks[frame]) for frame in chunks}
    return problem, world.truth(labels)


def _lidar_infos(world: World) -> tuple[LidarInfo, ...]:
    """What the reader reports of each LiDAR (perturbed extrinsics), sorted by frame."""
    infos = (
        LidarInfo(
            frame=mount.frame,
            topic=mount.topic,
            T_base_lidar=world.T_base_lidar_initial[i],
            scan_count=world.scan_count(i),
            points_per_second=mount.model.rate(world.rate_scale),
            scan_pattern=mount.model.scan_pattern,
        )
        for i, mount in enumerate(world.spec.lidars)
    )
    return tuple(sorted(infos, key=lambda lidar: lidar.frame))


def labels_of(scans: list[LabelledScan]) -> ScanLabels:
    """Concatenate the labels of scans (in message order) into the `labels.npz` layout."""
    sizes = np.array([len(s.is_bleeding) for s in scans], dtype=np.int64)

    def joined(name: str, dtype: type[np.generic]) -> NDArray[Any]:
        return np.concatenate([getattr(s, name) for s in scans]) if scans else np.zeros(0, dtype)

    return ScanLabels(
        stamps_ns=np.array([s.stamp_ns for s in scans], dtype=np.int64),
        offsets=np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
        is_bleeding=joined("is_bleeding", np.bool_),
        object_index=joined("object_index", np.int16),
        is_moving=joined("is_moving", np.bool_),
        is_spurious=joined("is_spurious", np.bool_),
    )
