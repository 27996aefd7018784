"""The routines a calibrating base drives, as routes: rotate in place, a square or rectangular
loop, a figure-eight and a back-and-forth lane.

Every move takes as long as the base's speed limits allow with a minimum-jerk profile (its peak
speed is the limit, its acceleration ramps from and to zero): `drive_mps` for straight drives,
`turn_dps` for turns, the slower of the two on arcs. Each routine starts at the world origin
heading along +x. `dwell_s` holds one dwell per stop, so stop durations can vary within one
recording; its length must be the routine's `stop_count`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from pydantic import BaseModel, ConfigDict, Field

from pipeline.errors import ConfigError
from pipeline.synth.motion import MIN_JERK_PEAK, Arc, RouteMotion, Segment, Straight


class Speeds(BaseModel):
    """Peak speeds of the base: forward (m/s) and turning (deg/s)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    drive_mps: float = Field(default=0.5, gt=0)
    turn_dps: float = Field(default=40.0, gt=0)

    def straight(self, distance_m: float) -> Straight:
        return Straight(
            distance_m=distance_m, duration_s=MIN_JERK_PEAK * abs(distance_m) / self.drive_mps
        )

    def arc(self, angle_deg: float, radius_m: float = 0.0) -> Arc:
        turning = abs(angle_deg) / self.turn_dps
        driving = abs(math.radians(angle_deg) * radius_m) / self.drive_mps
        return Arc(
            radius_m=radius_m,
            angle_deg=angle_deg,
            duration_s=MIN_JERK_PEAK * max(turning, driving),
        )


def _route(dwell_s: Sequence[float], legs: list[tuple[Segment, ...]], name: str) -> RouteMotion:
    if len(dwell_s) != len(legs) + 1:
        raise ConfigError(
            f"the {name} routine has {len(legs) + 1} stops but {len(dwell_s)} dwell times were "
            "given; pass one dwell per stop (see the routine's stop_count)"
        )
    return RouteMotion(dwell_s=tuple(dwell_s), legs=tuple(legs))


def rotate_in_place(step_deg: float, dwell_s: Sequence[float], speeds: Speeds) -> RouteMotion:
    """Turn on the spot by `step_deg` between stops (`len(dwell_s)` stops)."""
    legs: list[tuple[Segment, ...]] = [(speeds.arc(step_deg),)] * (len(dwell_s) - 1)
    return _route(dwell_s, legs, "rotate-in-place")


def side_stops(side_m: float, spacing_m: float) -> int:
    """Drives along one side of `side_m` with stops at most `spacing_m` apart."""
    return max(1, math.ceil(side_m / spacing_m - 1e-9))


def loop_stop_count(sides_m: tuple[float, float], spacing_m: float) -> int:
    """Stops along the four sides, the start, and one more at each of the three corners turned."""
    return 2 * (side_stops(sides_m[0], spacing_m) + side_stops(sides_m[1], spacing_m)) + 4


def loop(
    sides_m: tuple[float, float],
    spacing_m: float,
    dwell_s: Sequence[float],
    speeds: Speeds,
    left: bool = True,
) -> RouteMotion:
    """A rectangular loop (a square when both sides are equal) back to its start: straight
    drives with stops at most `spacing_m` apart, a stop at every corner, and a 90 deg turn on the
    spot at each corner before the next side (to the left, or to the right with `left=False`).

    A turn is a leg of its own, between two stops at the corner: a base that ends a drive at
    rest, turns and sets off again stands still at both ends of the turn, and a stop detector
    finds those rests whether or not the routine means them as stops."""
    turn = speeds.arc(90.0 if left else -90.0)
    legs: list[tuple[Segment, ...]] = []
    for side in range(4):
        length = sides_m[side % 2]
        count = side_stops(length, spacing_m)
        if side:
            legs.append((turn,))
        legs += [(speeds.straight(length / count),)] * count
    return _route(dwell_s, legs, "loop")


def figure_eight_stop_count(stops_per_circle: int) -> int:
    return 2 * stops_per_circle + 1


def figure_eight(
    radius_m: float, stops_per_circle: int, dwell_s: Sequence[float], speeds: Speeds
) -> RouteMotion:
    """Two circles of `radius_m` driven forward, the first to the left, the second to the
    right, meeting where the routine starts and ends; `stops_per_circle` stops on each."""
    step = 360.0 / stops_per_circle
    legs: list[tuple[Segment, ...]] = [(speeds.arc(step, radius_m),)] * stops_per_circle
    legs += [(speeds.arc(-step, -radius_m),)] * stops_per_circle
    return _route(dwell_s, legs, "figure-eight")


def lane_stop_count(length_m: float, spacing_m: float) -> int:
    return 2 * (side_stops(length_m, spacing_m) + 1)


def lane(
    length_m: float, spacing_m: float, dwell_s: Sequence[float], speeds: Speeds
) -> RouteMotion:
    """Down a straight lane of `length_m` with stops at most `spacing_m` apart, a turn round on
    the spot at its end (a stop before and after the turn), and back to the start."""
    count = side_stops(length_m, spacing_m)
    drive = speeds.straight(length_m / count)
    legs: list[tuple[Segment, ...]] = [(drive,)] * count + [(speeds.arc(180.0),)]
    legs += [(drive,)] * count
    return _route(dwell_s, legs, "lane")
