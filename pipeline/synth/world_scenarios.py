"""Named scenarios of the world options: set 1's robot in a room, among people walking by, on an
uneven floor, in dust, and all of them at once (`factory`). Tests use them; the randomised
scenarios draw the same options (`SceneSpec.room`, `walkers`, `floor`, `dust`) as further axes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pipeline.synth.dust import DustSpec
from pipeline.synth.floor import FloorSpec
from pipeline.synth.objects import ObjectKind
from pipeline.synth.room import RoomSpec
from pipeline.synth.scene import Ring, SceneSpec
from pipeline.synth.walkers import WalkerKind, WalkersSpec

if TYPE_CHECKING:
    from pipeline.synth.scenarios import ScenarioSpec

_KINDS = tuple(ObjectKind)
# Inside a room the low objects stand nearer the robot, between it and the shelves.
_ROOM_RING = Ring(r_min_m=0.9, r_max_m=1.6, count=(4, 6))


def world_scenarios(set1: ScenarioSpec) -> list[ScenarioSpec]:
    """The named world scenarios, on set 1's robot, LiDARs and routine (`set1`)."""
    room = RoomSpec()
    people = WalkersSpec(count=(2, 2))
    worlds = {
        "room": (
            "a closed room: walls 2-5 m away and 2-3 m tall, doorways, shelves 1.5-2 m tall "
            "along the walls, low objects in between",
            SceneSpec(object_kinds=_KINDS, rings=(_ROOM_RING,), room=room),
        ),
        "people": (
            "two people walking by at 0.5-1.5 m/s during the recording, mixed low objects",
            SceneSpec(object_kinds=_KINDS, walkers=people),
        ),
        "uneven-floor": (
            "an uneven floor: waves of 3-5 mm over 1-3 m, a 0.2-0.5 deg slope, a joint of 2-5 "
            "mm; the robot rests on it, its odometry stays planar",
            SceneSpec(object_kinds=_KINDS, floor=FloorSpec()),
        ),
        "dust": (
            "dust near the sensors: 0.3 % of the returns come from 0.1-1.5 m, weak",
            SceneSpec(object_kinds=_KINDS, dust=DustSpec()),
        ),
        "factory": (
            "everything at once: a room with shelves, people and a cart walking by, an uneven "
            "floor and dust",
            SceneSpec(
                object_kinds=_KINDS,
                rings=(_ROOM_RING,),
                room=room,
                walkers=people.model_copy(update={"kinds": (WalkerKind.PERSON, WalkerKind.CART)}),
                floor=FloorSpec(),
                dust=DustSpec(),
            ),
        ),
    }
    return [
        set1.model_copy(
            update={"name": name, "description": f"Set 1 LiDARs in {text}", "scene": scene}
        )
        for name, (text, scene) in worlds.items()
    ]
