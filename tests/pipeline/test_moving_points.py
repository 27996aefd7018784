"""Moving points within a stop: a box and a wall seen by every scan stay, a person walking in
front of the wall, somewhere else in each scan, goes."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.moving_points import MovingPointsConfig, find_moving_points, scan_ids

CONFIG = MovingPointsConfig()


def _directions(rng: np.random.Generator, n: int) -> np.ndarray:
    """Rosette-like: fresh random directions each scan, within 35 deg of +x."""
    azimuth = rng.uniform(-0.6, 0.6, n)
    elevation = rng.uniform(-0.6, 0.3, n)
    return np.column_stack(
        [
            np.cos(elevation) * np.cos(azimuth),
            np.cos(elevation) * np.sin(azimuth),
            np.sin(elevation),
        ]
    )


def _cast(directions: np.ndarray, person_y: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Each ray's first hit: a wall at x = 4, the floor at z = -1, a 0.4 m wide person (a slab at
    x = 2, from the floor up to z = 0.7) centred at `person_y`; and which hits are the person."""
    t_wall = 4.0 / directions[:, 0]
    t_floor = np.where(directions[:, 2] < 0, -1.0 / np.minimum(directions[:, 2], -1e-9), np.inf)
    t = np.minimum(t_wall, t_floor)
    on_person = np.zeros(len(directions), dtype=bool)
    if person_y is not None:
        t_person = 2.0 / directions[:, 0]
        hit = t_person[:, None] * directions
        on_person = (np.abs(hit[:, 1] - person_y) < 0.2) & (hit[:, 2] < 0.7) & (t_person < t)
        t = np.where(on_person, t_person, t)
    return directions * t[:, None], on_person


def _stop(scans: int, walking: bool, seed: int = 0) -> tuple[np.ndarray, list[int], np.ndarray]:
    rng = np.random.default_rng(seed)
    clouds, labels = [], []
    for k in range(scans):
        person_y = -1.0 + 0.12 * k if walking else None  # 1.2 m/s at 10 Hz
        points, on_person = _cast(_directions(rng, 3000), person_y)
        points += rng.normal(0, 0.01, points.shape)
        clouds.append(points)
        labels.append(on_person)
    return np.concatenate(clouds), [len(c) for c in clouds], np.concatenate(labels)


def test_a_static_stop_keeps_every_point() -> None:
    cloud, sizes, _ = _stop(12, walking=False)
    found = find_moving_points(cloud, sizes, CONFIG)
    assert not found.skipped
    assert not found.moving.any()


def test_a_person_walking_by_is_removed_and_the_wall_behind_kept() -> None:
    cloud, sizes, person = _stop(12, walking=True)
    assert person.sum() > 500
    found = find_moving_points(cloud, sizes, CONFIG)
    recall = (found.moving & person).sum() / person.sum()
    precision = (found.moving & person).sum() / max(found.moving.sum(), 1)
    assert recall > 0.8, recall
    assert precision > 0.95, precision
    assert found.seeds > 0


def test_a_stop_of_too_few_scans_is_not_judged() -> None:
    cloud, sizes, _ = _stop(CONFIG.min_scans - 1, walking=True)
    found = find_moving_points(cloud, sizes, CONFIG)
    assert found.skipped and not found.moving.any()


def test_disabled_keeps_every_point() -> None:
    cloud, sizes, _ = _stop(12, walking=True)
    found = find_moving_points(cloud, sizes, MovingPointsConfig(enabled=False))
    assert not found.moving.any()


def test_scan_sizes_must_add_up_to_the_cloud() -> None:
    cloud, sizes, _ = _stop(5, walking=False)
    with pytest.raises(ValueError, match="scan sizes add up"):
        find_moving_points(cloud, [*sizes[:-1], sizes[-1] - 1], CONFIG)


def test_scan_ids_number_points_by_their_scan() -> None:
    np.testing.assert_array_equal(scan_ids([2, 0, 3]), [0, 0, 2, 2, 2])


def test_a_stop_whose_scan_sizes_do_not_add_up_is_refused_where_it_is_made() -> None:
    from pipeline.problem import Stop

    with pytest.raises(ValueError, match="scan sizes of lidar_front add up to 5 points"):
        Stop(0, 0.0, 1.0, np.eye(4), {"lidar_front": np.zeros((4, 3))}, {}, {"lidar_front": (2, 3)})
