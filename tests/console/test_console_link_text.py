"""The fleet's link line, word for word, for what the ground knows of a
robot's link: its delay, when it was heard, no command waiting."""

from __future__ import annotations

from datetime import timedelta

from console_state import T0

from backend.core.model import UplinkCommand
from backend.protocol.messages import RobotInfo
from console.state.clock import MissionClock
from console.state.link import link_text


class _Model:
    def __init__(self, *infos: RobotInfo) -> None:
        self.robots = {i.name: i for i in infos}

    def pending(self, robot: str) -> list[UplinkCommand]:
        return []


def test_the_link_line_says_the_delay_and_when_it_was_heard():
    clock = MissionClock(lambda: T0 + timedelta(seconds=75))
    model = _Model(
        RobotInfo(name="lru1", online=True, delay_s=20.0, heard=T0),
        RobotInfo(name="lru2", online=True, heard=T0 + timedelta(seconds=70)),
        RobotInfo(name="lru3", online=True, delay_s=600.0),
    )
    assert link_text(model, "lru1", clock) == (
        "one-way delay 20s · heard 1m15s ago · no command waiting"
    )
    assert link_text(model, "lru2", clock) == "heard 5s ago · no command waiting"
    assert link_text(model, "lru3", clock) == "one-way delay 10m00s · no command waiting"
    assert link_text(model, "ardea", clock) == "no command waiting"
