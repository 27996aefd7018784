import numpy as np
import pytest
from numpy.typing import NDArray

from pipeline.segmentation import (
    SegmentationConfig,
    euclidean_clusters,
    find_floor,
    fit_floor,
    fit_plane,
    fit_plane_along_beams,
    patch_neighbours,
    segment,
    segment_on_floor,
)
from pipeline.surfaces import local_surfaces
from tests.pipeline.calibration_data import box_prepared, box_problem, floor_only_problem


def test_clusters_split_at_gaps_and_join_within_the_radius() -> None:
    rng = np.random.default_rng(0)
    blob = rng.uniform(0.0, 0.2, size=(300, 3))
    points = np.concatenate([blob, blob + np.array([1.0, 0.0, 0.0])])
    labels = euclidean_clusters(points, 0.05)
    assert len(np.unique(labels[:300])) == 1
    assert len(np.unique(labels[300:])) == 1
    assert labels[0] != labels[300]


def _floor_seen_obliquely_from_one_side(
    range_noise_m: float, n: int = 200_000
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """A floor 0.32 m below a LiDAR that sees it ahead only (0.3-1.5 m away, +-60 deg), with
    Gaussian range noise along the beams: points, the floor's normal and offset."""
    rng = np.random.default_rng(3)
    height = 0.32
    distance = rng.uniform(0.3, 1.5, n)
    bearing = np.radians(rng.uniform(-60.0, 60.0, n))
    floor = np.column_stack(
        [distance * np.cos(bearing), distance * np.sin(bearing), -np.full(n, height)]
    )
    ranges = np.linalg.norm(floor, axis=1, keepdims=True)
    noisy = floor / ranges * (ranges + rng.normal(0.0, range_noise_m, (n, 1)))
    return noisy, np.array([0.0, 0.0, 1.0]), height


def _tilt_deg(normal: NDArray[np.float64], truth: NDArray[np.float64]) -> float:
    return float(np.degrees(np.arccos(min(1.0, abs(float(normal @ truth))))))


def test_range_noise_tilts_a_least_squares_floor_but_not_one_fitted_along_the_beams() -> None:
    points, normal, offset = _floor_seen_obliquely_from_one_side(range_noise_m=0.03)
    least_squares, _, _ = fit_plane(points)
    assert _tilt_deg(least_squares, normal) > 0.1
    start = normal + np.array([0.01, -0.01, 0.0])  # about 0.8 deg off, as RANSAC leaves it
    along, along_offset, rms = fit_plane_along_beams(points, start / np.linalg.norm(start), 0.3)
    assert _tilt_deg(along, normal) < 0.02
    assert along_offset == pytest.approx(offset, abs=2e-4)
    assert along @ normal > 0  # oriented as the start
    assert 0.005 < rms < 0.03


def test_a_floor_fitted_along_the_beams_is_exact_without_noise() -> None:
    points, normal, offset = _floor_seen_obliquely_from_one_side(range_noise_m=0.0, n=1000)
    along, along_offset, rms = fit_plane_along_beams(points, normal, offset + 0.01)
    assert _tilt_deg(along, normal) < 1e-6
    assert along_offset == pytest.approx(offset, abs=1e-9)
    assert rms < 1e-9


def test_a_floor_seen_along_one_line_keeps_its_undetermined_tilt() -> None:
    along_x = np.linspace(0.5, 2.0, 50)
    points = np.column_stack([along_x, np.zeros(50), np.full(50, -0.5)])
    start = np.array([0.0, 0.01, 1.0])
    start /= np.linalg.norm(start)
    normal, offset, rms = fit_plane_along_beams(points, start, 0.5)
    assert np.all(np.isfinite(normal)) and np.isfinite(offset)
    assert normal[1] == pytest.approx(start[1], abs=1e-5)  # the tilt about x: nothing fixes it
    assert rms < 1e-9


def test_find_floor_fits_along_the_beams_when_asked() -> None:
    points, normal, _ = _floor_seen_obliquely_from_one_side(range_noise_m=0.03)
    tilts = {}
    for along_beams in (False, True):
        found = _floor_of(points, normal, iterations=200, along_beams=along_beams)
        assert found is not None
        tilts[along_beams] = _tilt_deg(found[0], normal)
    assert tilts[True] < 0.05 < tilts[False]


def test_floor_is_the_plane_facing_up_not_the_larger_wall() -> None:
    rng = np.random.default_rng(1)
    floor = np.column_stack([rng.uniform(-2, 2, (3000, 2)), np.full(3000, -0.8)])
    wall = np.column_stack([np.full(6000, 3.0), rng.uniform([-2, -0.7], [2, 2], (6000, 2))])
    up = np.array([0.0, 0.0, 1.0])
    found = find_floor(
        np.concatenate([floor, wall]),
        up,
        distance_m=0.02,
        iterations=200,
        scored_points=2000,
        max_tilt_deg=30,
        min_points=100,
        rng=np.random.default_rng(0),
    )
    assert found is not None
    plane, inliers, _ = found
    np.testing.assert_allclose(plane.normal, up, atol=1e-6)
    assert abs(plane.offset - 0.8) < 1e-6
    assert inliers[:3000].all() and not inliers[3000:].any()


def test_floor_and_objects_of_a_synthetic_recording_match_the_truth() -> None:
    _, truth = box_problem()
    prepared, segments = box_prepared()
    true = {lidar.frame: lidar.T_base_lidar_true for lidar in truth.lidars}
    config = SegmentationConfig()
    for lidar, row in zip(prepared.lidars, segments, strict=True):
        # base_link lies on the floor: in the LiDAR frame the floor's normal is base z and its
        # offset the LiDAR's height.
        T = true[lidar.frame]
        normal, height = T[:3, :3].T @ [0.0, 0.0, 1.0], T[2, 3]
        objects = 0
        for segmentation in row:
            assert segmentation.floor is not None
            angle = np.degrees(np.arccos(np.clip(segmentation.floor.normal @ normal, -1, 1)))
            assert angle < 0.2
            assert abs(segmentation.floor.offset - height) < 0.005
            above = segmentation.object_points @ normal + height
            # Smoothed along its beam, a point at an object's foot can move a few centimetres.
            assert np.all(above > config.object_min_height_m - 0.04)
            assert np.all(above < 0.35)  # the objects are 0.25 m tall
            objects += len(segmentation.object_points)
        assert objects > 1000


def test_a_bare_floor_yields_almost_no_object_points() -> None:
    problem, _ = floor_only_problem()
    lidar = problem.lidars[0]
    up = lidar.T_base_lidar[:3, :3].T @ [0.0, 0.0, 1.0]
    total = sum(
        len(segment(stop.clouds[lidar.frame], up, SegmentationConfig()).object_points)
        for stop in problem.stops
    )
    assert total < 50


def test_a_floor_fitted_beforehand_gives_the_same_segmentation() -> None:
    problem, _ = box_problem()
    lidar = problem.lidars[0]
    up = lidar.T_base_lidar[:3, :3].T @ [0.0, 0.0, 1.0]
    cloud = problem.stops[0].clouds[lidar.frame]
    config = SegmentationConfig()
    fitted = fit_floor(cloud, up, config)
    assert fitted is not None

    given, own = segment_on_floor(cloud, config, fitted), segment(cloud, up, config)

    np.testing.assert_array_equal(given.object_points, own.object_points)
    assert given.floor_inliers == own.floor_inliers
    assert segment_on_floor(cloud, config, None).object_points.shape == (0, 3)


def _room(rng: np.random.Generator, floor_points: int) -> tuple[np.ndarray, np.ndarray]:
    """A sensor 1.5 m above the floor (z = -1.5) in a 6 m square room with 2 m tall walls: the
    floor (a disc of 1.5 m radius, as much as the walls and shelves leave in view) first, then
    8000 wall points. And the up direction of initial extrinsics 10 deg off the true one."""
    radius, angle = 1.5 * np.sqrt(rng.uniform(size=floor_points)), rng.uniform(0, 6.3, floor_points)
    floor = np.column_stack([radius * np.cos(angle), radius * np.sin(angle), -1.5 + 0 * angle])
    along, height = rng.uniform(-3, 3, 8000), rng.uniform(-1.5, 0.5, 8000)
    side = rng.integers(0, 4, 8000)
    wall = np.column_stack([along, np.full(8000, 3.0), height])
    for quarter in range(1, 4):  # the other three walls: the first turned about z
        c, s = np.cos(quarter * np.pi / 2), np.sin(quarter * np.pi / 2)
        turned = wall[side == quarter]
        wall[side == quarter, :2] = turned[:, :2] @ np.array([[c, s], [-s, c]])
    up = np.array([np.sin(np.radians(10)), 0.0, np.cos(np.radians(10))])
    return np.concatenate([floor, wall]), up


def _floor_of(
    points: np.ndarray,
    up: np.ndarray,
    *,
    iterations: int = 100,
    seed: int = 0,
    along_beams: bool = False,
) -> tuple[np.ndarray, float] | None:
    found = find_floor(
        points,
        up,
        distance_m=0.02,
        iterations=iterations,
        scored_points=2000,
        max_tilt_deg=30,
        min_points=100,
        rng=np.random.default_rng(seed),
        along_beams=along_beams,
    )
    return None if found is None else (found[0].normal, found[0].offset)


def _assert_the_rooms_floor(floor: tuple[np.ndarray, float] | None, seed: int = 0) -> None:
    """`_room`'s floor: level within 0.2 deg, 1.5 m below the sensor within 5 mm."""
    assert floor is not None, seed
    assert floor[0][2] > np.cos(np.radians(0.2)), seed
    assert abs(floor[1] - 1.5) < 0.005, seed


def test_the_floor_is_found_where_walls_fill_most_of_the_cloud() -> None:
    # 600 floor points among 8600: three random points are all floor once in 3000 draws; the
    # lowest points of the columns across up are mostly floor (the walls stand on it).
    points, up = _room(np.random.default_rng(2), 600)
    _assert_the_rooms_floor(_floor_of(points, up))


def test_the_floor_is_not_a_larger_plane_with_the_floor_below_it() -> None:
    # A long shelf top along a wall, 0.5 m above the floor, with more points than the floor in
    # view and a third of the columns: the floor lies below it, which no LiDAR could see were
    # the shelf top the floor.
    rng = np.random.default_rng(3)
    room, up = _room(rng, 600)
    top = rng.uniform([1.6, -2.9], [2.9, 2.9], (2000, 2))
    shelf = np.column_stack([top, np.full(2000, -1.0)])
    _assert_the_rooms_floor(_floor_of(np.concatenate([room, shelf]), up))


def test_a_floor_seen_only_as_a_far_strip_is_found_whatever_the_draws() -> None:
    # Walls 3 m away whose feet are hidden (seen from 0.5 m above the floor up), the floor only
    # as a strip 2.6-2.9 m away over a quarter turn: 38 of the 169 columns' lowest points.
    rng = np.random.default_rng(4)
    room, up = _room(rng, 0)
    walls = room[room[:, 2] > -1.0]
    radius, angle = rng.uniform(2.6, 2.9, 400), rng.uniform(0, np.pi / 2, 400)
    strip = np.column_stack([radius * np.cos(angle), radius * np.sin(angle), np.full(400, -1.5)])
    points = np.concatenate([strip, walls])
    iterations = SegmentationConfig().ransac_iterations
    for seed in range(10):
        _assert_the_rooms_floor(_floor_of(points, up, iterations=iterations, seed=seed), seed)


def _noisy_wall(spacing_m: float, noise_m: float, seed: int = 0) -> NDArray[np.float64]:
    """A 1.2 m square wall 2 m in front of the sensor (at the origin), sampled on a jittered
    grid of `spacing_m`, each point moved along its beam by Gaussian range noise `noise_m`."""
    rng = np.random.default_rng(seed)
    side = np.arange(-0.6, 0.6, spacing_m)
    y, z = (a.ravel() for a in np.meshgrid(side, side))
    points = np.column_stack([np.full(len(y), 2.0), y, z])
    points[:, 1:] += rng.uniform(-0.3, 0.3, (len(y), 2)) * spacing_m
    beams = points / np.linalg.norm(points, axis=1, keepdims=True)
    noisy: NDArray[np.float64] = points + beams * rng.normal(0.0, noise_m, len(points))[:, None]
    return noisy


@pytest.mark.parametrize(
    ("spacing_m", "noise_m", "low", "high"),
    [
        (0.02, 0.02, 65, 95),  # the reference: about the fixed patch
        # Twice the noise: more points, though not quite twice as many (a 3-D patch of a sheet
        # 8 cm thick favours the point's own side, so the noise measures about 20 % low).
        (0.02, 0.04, 105, 170),
        (0.04, 0.02, 30, 50),  # half the density along each axis: half the points
    ],
)
def test_a_noise_scaled_patch_grows_with_the_noise_and_shrinks_with_the_spacing(
    spacing_m: float, noise_m: float, low: int, high: int
) -> None:
    config = SegmentationConfig(surface_patch="noise", surface_neighbours=80)
    wall = _noisy_wall(spacing_m, noise_m)
    assert low <= patch_neighbours(wall, local_surfaces(wall, 80), config) <= high


def test_a_cloud_whose_noise_cannot_be_measured_keeps_the_fixed_patch() -> None:
    config = SegmentationConfig(surface_patch="noise", surface_neighbours=80)
    small = _noisy_wall(0.2, 0.02)  # 36 points: fewer than a patch
    assert patch_neighbours(small, local_surfaces(small, 80), config) == 80
    exact = _noisy_wall(0.02, 0.0)  # no noise to scale by
    assert patch_neighbours(exact, local_surfaces(exact, 80), config) == 80
