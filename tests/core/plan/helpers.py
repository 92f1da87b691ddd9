"""A small library, missions built in a line per robot, and a fake site map
for the plan tests (predictions and checks)."""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from backend.core.library import Library
from backend.core.model import Barrier, Mission, RobotSpec, SkillInstance, Status
from backend.core.plan.geometry import Point, distance

T0 = 1_900_000_000.0  # the tests' "now", wall seconds

LIBRARY = Library.model_validate(
    {
        "name": "plan-tests",
        "robot_types": {
            "rover": {
                "skills": ["drive", "work", "charge", "survey", "link", "meet", "pair"],
                "speed_mps": 1.0,
                "battery": {
                    "reserve": 0.05,
                    "margin": 0.2,
                    "per_metre": 0.001,
                    "per_s": 0.0,
                    "charge_per_s": 0.01,
                },
            },
            "drone": {
                "skills": ["fly", "work", "charge", "survey"],
                "speed_mps": 2.0,
                "flies": True,
                "survey_m2_per_s": 10.0,
                "battery": {"reserve": 0.05, "margin": 0.2, "per_s": 0.001, "charge_per_s": 0.01},
            },
            "base": {"kind": "static", "skills": ["work"]},
        },
        "skills": {
            "drive": {
                "params": {
                    "goal": {"type": "pose"},
                    "speed": {"type": "float", "default": 1.0, "min": 0.1, "max": 5.0},
                },
                "duration": {"base_s": 0, "goal_param": "goal", "speed_param": "speed"},
            },
            "fly": {
                "params": {"goal": {"type": "position"}},
                "duration": {"base_s": 10, "goal_param": "goal"},
            },
            "work": {
                "params": {"seconds": {"type": "float", "default": 100, "min": 0, "max": 1e5}},
                "duration": {"base_s": 0, "per_param_s": {"seconds": 1.0}},
                "energy": {"per_s": 0.0001},
            },
            "charge": {
                "params": {"level": {"type": "float", "default": 1.0, "min": 0.1, "max": 1.0}},
                "duration": {"base_s": 0, "to_home": True, "charge_param": "level"},
            },
            "survey": {
                "params": {
                    "area": {"type": "area"},
                    "seconds": {"type": "float", "default": 60, "min": 1, "max": 1e5},
                },
                "duration": {"base_s": 0, "per_param_s": {"seconds": 1.0}, "area_param": "area"},
            },
            "link": {"duration": {"base_s": 30}, "needs_comms": True},
            "meet": {
                "params": {"partner": {"type": "robot", "required": False}},
                "duration": {"base_s": 50},
            },
            "pair": {  # works at a place with a partner it talks to
                "params": {
                    "place": {"type": "position"},
                    "partner": {"type": "robot", "required": False},
                },
                "duration": {"base_s": 50, "goal_param": "place"},
                "talks_to": "partner",
            },
        },
    }
)


def at(t: float) -> datetime:
    return datetime.fromtimestamp(t, UTC)


def skill(sid: str, name: str, status: str = "idle", **params: Any) -> SkillInstance:
    s = SkillInstance(id=sid, skill=name, params=params, status=Status(status))
    if s.status in (Status.RUNNING, Status.PAUSED, Status.SUCCESS, Status.FAILURE):
        s.started_at = at(T0 - 10)
    if s.status in (Status.SUCCESS, Status.FAILURE):
        s.finished_at = at(T0 - 5)
    return s


def pose(x: float, y: float) -> dict[str, float]:
    return {"x": x, "y": y, "z": 0.0, "roll": 0.0, "pitch": 0.0, "yaw": 0.0}


def mission(
    robots: dict[str, str],
    tasks: dict[str, list[SkillInstance]],
    barriers: dict[str, list[str]] | None = None,
) -> Mission:
    m = Mission(library="plan-tests.yaml")
    m.robots = {r: RobotSpec(type=t) for r, t in robots.items()}
    m.tasks = {r: tasks.get(r, []) for r in robots}
    m.barriers = {b: Barrier(skills=ids) for b, ids in (barriers or {}).items()}
    return m


@dataclass
class FakeSite:
    """A site map given by functions of (x, y): coverage within `radius` of
    the origin, rocks and unexplored ground as sets of integer cells."""

    radius: float = 50.0
    rocks: set[tuple[int, int]] = field(default_factory=set)
    unexplored: set[tuple[int, int]] = field(default_factory=set)
    walls: bool = False  # no route anywhere past x = 100
    version: int = 0
    home_at: Point | None = (0.0, 0.0)
    detour: float = 1.0  # route length = straight line x detour

    def covered(self, x: float, y: float) -> bool | None:
        return distance((0.0, 0.0), (x, y)) <= self.radius

    def passable(self, x: float, y: float) -> bool | None:
        return (round(x), round(y)) not in self.rocks

    def explored(self, x: float, y: float) -> bool | None:
        return (round(x), round(y)) not in self.unexplored

    def route_length(self, a: Point, b: Point) -> float:
        if self.walls and max(a[0], b[0]) > 100:
            return float("inf")
        return distance(a, b) * self.detour

    def home(self) -> Point | None:
        return self.home_at
