"""The timeline's selected skill is drawn whatever the zoom, when it is the
lane's robot's and in the window (the forecast's window leaves some out)."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from backend.core.model import Mission, SkillInstance
from backend.core.plan.forecast import SkillForecast
from console.state import timeline as tl
from console.state.clock import MissionClock

NOW = datetime(2026, 3, 14, 10, 42, 7, tzinfo=UTC).timestamp()
WALL = MissionClock(lambda: datetime.fromtimestamp(NOW, UTC))


def _predicted(sid: str, robot: str, start: float, end: float) -> SkillForecast:
    skill = SkillInstance(id=sid, skill="recharge")
    return SkillForecast(sid, robot, start, start, end, None, None, None, None, None, (), skill)


class _Zoomed:
    """A forecast whose window, at this zoom, shows only the first skill."""

    def __init__(self, *skills: SkillForecast) -> None:
        self.skills = {f.id: f for f in skills}

    def window(self, robot: str, t0: float, t1: float, step: float = 0.0) -> Any:
        return [f for f in self.skills.values() if f.robot == robot][:1]

    def skill(self, sid: str) -> SkillForecast | None:
        return self.skills.get(sid)


def test_the_selected_skill_is_drawn_when_in_the_window_and_the_lanes():
    fc: Any = _Zoomed(
        _predicted("lru1-1", "lru1", NOW, NOW + 10),
        _predicted("lru1-2", "lru1", NOW + 10, NOW + 20),
        _predicted("lru1-3", "lru1", NOW + 500, NOW + 600),
        _predicted("lru2-1", "lru2", NOW + 10, NOW + 20),
    )
    mission = Mission.model_construct(tasks={})  # no log: only predictions

    def shown(also: str | None) -> list[str]:
        return [b.id for b in tl.bars(mission, fc, "lru1", WALL, NOW, NOW + 100, 60, also)]

    assert shown(None) == ["lru1-1"]
    assert shown("lru1-2") == ["lru1-1", "lru1-2"]
    assert shown("lru1-1") == ["lru1-1"]  # drawn once
    assert shown("lru1-3") == ["lru1-1"]  # after the window
    assert shown("lru2-1") == ["lru1-1"]  # another robot's lane
    assert shown("lru1-9") == ["lru1-1"]  # no prediction
