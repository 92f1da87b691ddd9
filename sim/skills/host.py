"""What skill handlers need from the fleet that runs them (sim/fleet.py's SimFleet is one).

Skills depend on this protocol, never on the fleet: the fleet imports the skills to
register them, so the skills importing the fleet back would tie the two together.
Tests host skills with a plain namespace holding these names.
"""

from __future__ import annotations

from typing import Any, Protocol

from sim.robot import SimRobot
from sim.world import World


class SkillHost(Protocol):
    world: World
    """The site the robots move in: its truth, its ground view and the referee's log."""

    dt: float
    """Sim seconds per skill step (set from the sim speed)."""

    robot_seconds: float
    """Sim seconds stepped by the skills of every robot together (the host's account)."""

    def note(self, robot: SimRobot, text: str) -> None:
        """Keep the outcome of a skill for the sim status (a success report has no text)."""

    async def ask(
        self, sender: SimRobot, target: str, topic: str, data: dict[str, Any]
    ) -> dict[str, Any] | None:
        """`sender` asks robot `target` about `topic`: the answer, or None (unknown or
        out of reach)."""

    async def tell(self, sender: SimRobot, target: str, topic: str, data: dict[str, Any]) -> bool:
        """`sender` tells robot `target` about `topic`: False when `target` is out of reach."""
