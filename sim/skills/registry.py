"""The skills the simulator offers: skill name -> handler, in one table.

A robot offers the skills its type lists in the library (missions/libraries/mars.yaml)
that are in this table; the fleet warns about the others and refuses to sync them.
"""

from __future__ import annotations

from collections.abc import Callable
from types import MethodType
from typing import Any

from sim.skills.aerial import AerialSkills
from sim.skills.manipulation import ManipulationSkills
from sim.skills.mobility import MobilitySkills
from sim.skills.power import PowerSkills
from sim.skills.science import ScienceSkills

SKILLS: dict[str, Callable[..., Any]] = {
    "drive_to": MobilitySkills.drive_to,
    "explore": MobilitySkills.explore,
    "take_science_image": ScienceSkills.take_science_image,
    "identify_stone": ScienceSkills.identify_stone,
    "pick_stone": ManipulationSkills.pick_stone,
    "drop_stone": ManipulationSkills.drop_stone,
    "pick_payload_box": ManipulationSkills.pick_payload_box,
    "place_payload_box": ManipulationSkills.place_payload_box,
    "deploy_wifi_box": ManipulationSkills.deploy_wifi_box,
    "recharge": PowerSkills.recharge,
    "takeoff": AerialSkills.takeoff,
    "fly_to": AerialSkills.fly_to,
    "land": AerialSkills.land,
    "load_box": ManipulationSkills.load_box,
}


class RobotSkills(MobilitySkills, ScienceSkills, ManipulationSkills, AerialSkills, PowerSkills):
    """Every skill handler of one simulated robot: the families' methods on one object."""

    def handlers(self) -> dict[str, Callable[..., Any]]:
        """Skill name -> this robot's handler `fn(ctx, **params)`, for every skill of SKILLS."""
        return {name: MethodType(fn, self) for name, fn in SKILLS.items()}
