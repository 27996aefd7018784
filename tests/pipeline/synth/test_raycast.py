"""Ray casting hits the true geometry; bleeding points float at depth discontinuities only."""

from __future__ import annotations

import math

import numpy as np

from pipeline.synth.raycast import cast, cast_with_footprint, segments_near
from pipeline.synth.scene import ObjectKind, Scene, SceneObject, SceneSpec, build_scene
from pipeline.transforms import from_xyz_rpy

BOX = SceneObject(
    kind=ObjectKind.BOX,
    dimensions={"x": 0.4, "y": 0.4, "z": 0.25},
    T_world_object=from_xyz_rpy([2.0, 0.0, 0.125], [0.0, 0.0, 0.0]),
    reflectivity=0.5,
)
ORIGIN = np.array([0.0, 0.0, 0.9])


def _scene() -> Scene:
    return build_scene(SceneSpec(), [BOX])


def _grid_towards_box(n: int = 160) -> np.ndarray:
    """Unit rays covering the box and the floor round and behind it."""
    yaw = np.radians(np.linspace(-10.0, 10.0, n))
    pitch = np.radians(np.linspace(14.0, 30.0, n))
    yy, pp = np.meshgrid(yaw, pitch)
    return np.column_stack(
        [
            np.cos(pp.ravel()) * np.cos(yy.ravel()),
            np.cos(pp.ravel()) * np.sin(yy.ravel()),
            -np.sin(pp.ravel()),
        ]
    )


def _inside_box(points: np.ndarray, margin: float) -> np.ndarray:
    local = points - BOX.T_world_object[:3, 3]
    half = np.array([0.2, 0.2, 0.125]) + margin
    return np.asarray(np.all(np.abs(local) <= half, axis=1))


def _box_distance(points: np.ndarray) -> np.ndarray:
    """Euclidean distance from points outside the (axis-aligned) box to it; 0 inside."""
    excess = np.abs(points - BOX.T_world_object[:3, 3]) - np.array([0.2, 0.2, 0.125])
    return np.asarray(np.linalg.norm(np.maximum(excess, 0.0), axis=1))


def test_hits_lie_on_floor_or_box_and_the_robot_is_ignored() -> None:
    scene = _scene()
    directions = _grid_towards_box()
    hits = cast(scene, ORIGIN, directions, max_range=40.0)
    assert np.all(hits.geom >= 0)
    points = ORIGIN + directions * hits.range_m[:, None]
    on_box = scene.geom_object[hits.geom] == 0
    np.testing.assert_allclose(points[~on_box, 2], 0.0, atol=1e-9)
    assert _inside_box(points[on_box], 1e-9).all()
    assert 0.05 < on_box.mean() < 0.6
    # Straight down from the LiDAR passes through the robot's chassis at the origin: ignored.
    down = cast(scene, ORIGIN, np.array([[0.0, 0.0, -1.0]]), max_range=40.0)
    assert down.range_m[0] == np.float64(0.9) or abs(down.range_m[0] - 0.9) < 1e-9


def test_hits_on_every_kind_of_object_lie_on_its_surface() -> None:
    objects = [
        SceneObject(
            ObjectKind.BOX,
            {"x": 0.3, "y": 0.5, "z": 0.25},
            from_xyz_rpy([2, 0, 0.125], [0, 0, 0.4]),
            0.5,
        ),
        SceneObject(
            ObjectKind.CYLINDER,
            {"radius": 0.2, "height": 0.25},
            from_xyz_rpy([0, 2, 0.125], [0, 0, 0]),
            0.5,
        ),
        SceneObject(
            ObjectKind.CAPSULE,
            {"radius": 0.125, "length": 0.4},
            from_xyz_rpy([-2, 0, 0.125], [0, 0, 1.0]),
            0.5,
        ),
    ]
    scene = build_scene(SceneSpec(), objects)
    rng = np.random.default_rng(1)
    directions = rng.normal(size=(20000, 3))
    directions[:, 2] = -np.abs(directions[:, 2]) * 0.4
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    hits = cast(scene, ORIGIN, directions, max_range=40.0)
    hit = hits.geom >= 0
    points = ORIGIN + directions[hit] * hits.range_m[hit, None]
    distance, nearest = scene.nearest_surface(points)
    assert distance.max() < 1e-6
    np.testing.assert_array_equal(nearest, scene.geom_object[hits.geom[hit]])
    assert set(nearest.tolist()) == {-1, 0, 1, 2}


def test_misses_beyond_range_give_inf() -> None:
    hits = cast(_scene(), ORIGIN, np.array([[1.0, 0.0, 0.0], [0.6, 0.0, -0.8]]), max_range=1.0)
    assert np.isinf(hits.range_m).all() and (hits.geom == -1).all()


def test_bleeding_points_float_between_an_edge_and_the_background() -> None:
    scene = _scene()
    directions = _grid_towards_box()
    returns = cast_with_footprint(
        scene,
        ORIGIN,
        directions,
        max_range=40.0,
        footprint_deg=0.35,
        label_margin_m=0.06,
        rng=np.random.default_rng(0),
    )
    points = ORIGIN + directions * returns.range_m[:, None]
    bleeding = returns.is_bleeding
    assert 0.002 < bleeding.mean() < 0.1
    # Every labelled point is off both surfaces by more than the margin...
    assert np.all(points[bleeding, 2] > 0.06)
    assert np.all(_box_distance(points[bleeding]) > 0.06)
    # ...and every other point is on one of them (no noise is added at this level).
    clean = points[~bleeding]
    on_surface = (np.abs(clean[:, 2]) < 0.06) | _inside_box(clean, 0.06)
    assert on_surface.all()
    # Each labelled ray passes within its footprint of the box's silhouette: a finer ring of
    # rays round it sees both the box and the floor.
    footprint = math.radians(0.35)
    for direction in directions[bleeding][:: max(1, bleeding.sum() // 40)]:
        helper = np.array([0.0, 0.0, 1.0])
        u = np.cross(direction, helper)
        u /= np.linalg.norm(u)
        v = np.cross(direction, u)
        phase = np.linspace(0, 2 * math.pi, 48, endpoint=False)
        ring = math.cos(footprint) * direction + math.sin(footprint) * (
            np.cos(phase)[:, None] * u + np.sin(phase)[:, None] * v
        )
        seen = set(scene.geom_object[cast(scene, ORIGIN, ring, 40.0).geom].tolist())
        assert seen == {-1, 0}


def test_no_footprint_means_no_bleeding() -> None:
    returns = cast_with_footprint(
        _scene(),
        ORIGIN,
        _grid_towards_box(40),
        max_range=40.0,
        footprint_deg=0.0,
        label_margin_m=0.06,
        rng=np.random.default_rng(0),
    )
    assert not returns.is_bleeding.any()


def test_the_segments_near_a_sphere_hold_every_one_the_exact_test_passes() -> None:
    # The cull before each exact test must keep every ray that test passes: rays from origins
    # spread over a few centimetres, spheres near and far, a wide footprint, short and long rays.
    rng = np.random.default_rng(3)
    n, footprint = 20_000, math.radians(1.5)
    origins = np.array([0.0, 0.0, 0.9]) + rng.normal(0.0, 0.02, (n, 3))
    directions = rng.normal(size=(n, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    centres = np.vstack([rng.uniform(-4.0, 4.0, (12, 3)), [[0.05, 0.0, 0.9]]])
    radius = rng.uniform(0.05, 0.6, len(centres))
    reach = rng.uniform(0.5, 8.0, n)
    candidates = segments_near(
        centres, radius, origins, directions, reach, reach * math.tan(footprint)
    )
    for rows, centre, r in zip(candidates, centres, radius, strict=True):
        # The exact test, ray by ray: the nearest point of the ray (up to its reach) to the
        # centre, within the radius widened by the footprint there.
        along = np.einsum("ij,ij->i", directions, centre - origins)
        closest = np.clip(along, 0.0, reach)
        gap = np.linalg.norm(origins + closest[:, None] * directions - centre, axis=1)
        near = np.flatnonzero(gap <= r + closest * math.tan(footprint))
        assert len(near) > 0
        assert np.isin(near, rows).all()
    # ... and leaves most rays out (the point of it) for a sphere away from the origins.
    assert min(len(rows) for rows in candidates) < n / 10
