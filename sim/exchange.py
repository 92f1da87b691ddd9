"""What a simulated robot answers when another robot asks or tells it about the world.

Each robot answers from its own world model (`SimRobot.knowledge`), and only to
robots it can talk to (`World.can_talk`); the fleet registers these handlers on
the robot's agent (`RobotAgent.on_ask` / `on_tell`). The asking side is
`SimFleet.ask` / `tell`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from backend.agent import RobotAgent
from sim.robot import SimRobot
from sim.world import World

Data = dict[str, Any]


class WorldExchange:
    """The ask and tell handlers of one robot, by topic."""

    def __init__(self, world: World, robot: SimRobot):
        self.world = world
        self.robot = robot

    def register(self, agent: RobotAgent) -> None:
        for topic, answer in self.asks().items():
            agent.on_ask(topic, answer)
        for topic, receive in self.tells().items():
            agent.on_tell(topic, receive)

    def asks(self) -> dict[str, Callable[[Data, str], Data | None]]:
        return {
            "stone": self.ask_stone,
            "rss": self.ask_rss,
            "box": self.ask_box,
            "pose": self.ask_pose,
            "shelf": self.ask_shelf,
        }

    def tells(self) -> dict[str, Callable[[Data, str], None]]:
        return {"box": self.tell_box, "stone": self.tell_stone, "rss": self.tell_rss}

    def reachable(self, sender: str) -> bool:
        other = self.world.robots.get(sender)
        return other is not None and self.world.can_talk(self.robot, other)

    # ------------------------------------------------------------ asks

    def ask_stone(self, data: Data, sender: str) -> Data | None:
        """The best-scored pickable stone it knows within `radius` of (x, y), leaving out
        those the asker knows to be gone (`exclude`: id -> version) unless its own news of
        one is newer."""
        if not self.reachable(sender):
            return None
        x, y, radius = (
            float(data.get("x", 0)),
            float(data.get("y", 0)),
            float(data.get("radius", 5)),
        )
        exclude = data.get("exclude") or {}
        cands = [
            s
            for s in self.robot.knowledge.stones.values()
            if pickable_near(s, x, y, radius) and not _known_gone(s, exclude)
        ]
        if not cands:
            return None
        best: Data = min(cands, key=lambda s: best_first(s, x, y))
        return dict(best)

    def ask_rss(self, data: Data, sender: str) -> Data | None:
        rss = self.robot.knowledge.rss
        if not self.reachable(sender) or not rss:
            return None
        return {"regions": [dict(v) for v in rss.values()]}

    def ask_box(self, data: Data, sender: str) -> Data | None:
        if not self.reachable(sender):
            return None
        info = self.robot.knowledge.boxes.get(str(data.get("box", "")))
        return dict(info) if info is not None else None

    def ask_pose(self, data: Data, sender: str) -> Data | None:
        if not self.reachable(sender):
            return None
        r = self.robot
        return {
            "x": round(r.x, 2),
            "y": round(r.y, 2),
            "yaw": round(r.yaw, 3),
            "airborne": r.airborne,
        }

    def ask_shelf(self, data: Data, sender: str) -> Data | None:
        """Slot -> box on the shelf (the lander only: it sees its shelf)."""
        if self.robot.kind != "static" or not self.reachable(sender):
            return None
        slots = {
            str(b.slot): b.name
            for b in self.world.boxes.values()
            if b.where == "shelf" and b.slot is not None
        }
        return {"slots": slots}

    # ------------------------------------------------------------ tells

    def tell_box(self, data: Data, sender: str) -> None:
        if self.reachable(sender) and "box" in data:
            self.robot.knowledge.boxes[str(data["box"])] = dict(data)

    def tell_stone(self, data: Data, sender: str) -> None:
        if self.reachable(sender) and "id" in data:
            self.robot.knowledge.learn_stone(data)  # unless its own news is newer

    def tell_rss(self, data: Data, sender: str) -> None:
        if self.reachable(sender) and "rss" in data:
            self.robot.knowledge.learn_rss(data)  # a revealed top score stays


def pickable_near(s: Data, x: float, y: float, radius: float) -> bool:
    """A stone of a world model an arm can pick, within `radius` of (x, y)."""
    return (
        s.get("state") in ("identified", "ground") and math.hypot(s["x"] - x, s["y"] - y) <= radius
    )


def _known_gone(s: Data, exclude: dict[str, int]) -> bool:
    """The asker knew the stone gone at this version of it or a later one."""
    return int(s.get("v", 0)) <= int(exclude.get(s["id"], -1))


def best_first(s: Data, x: float, y: float) -> tuple[float, float]:
    """A stone's rank: the best score first, the nearest to (x, y) among equals."""
    return (-(s.get("score") or 0), math.hypot(s["x"] - x, s["y"] - y))
