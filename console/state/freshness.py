"""How fresh what the console knows of a robot is (no Textual here).

The ground's view of a robot is its last report: when the robot is offline,
has stopped sending the telemetry it was sending, or is so far away that
what arrives is old, that view is the robot's *last known* state, not a live
one. The schedule then draws it dimmed with "as of 25s ago", and progress and
ETA stop (they are not extrapolated).

When it was last heard is the later of the console's own arrival stamps
(telemetry, a report) and the server's (RobotInfo.heard: registration, any
downlink message). A robot's estimated one-way delay (RobotInfo.delay_s) is
added: what arrives now left the robot that long ago. A delay of
`SILENT_AFTER_S` or more makes the robot stale even while its messages keep
arriving in order ("delayed"). A robot out of contact (its window closed,
RobotInfo.contact) is stale too, whatever it sent last ("out of contact").
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Any, Protocol

from backend.protocol.messages import RobotInfo, Telemetry
from console.state.clock import MissionClock
from console.state.contact import out_of_contact
from console.state.text import fmt_duration

# a robot that was sending telemetry and has been silent this long is stale
# (the sim sends 4 per second; a hung robot keeps its presence until its lease ends)
SILENT_AFTER_S = 10.0


@dataclass(frozen=True)
class Freshness:
    """`stale`: draw the robot's state as last known; `age_s`: since when, in
    mission seconds (None: never heard); `why`: "offline", "out of contact",
    "silent", "delayed" or "" (fresh)."""

    stale: bool = False
    age_s: float | None = None
    why: str = ""

    def as_of(self) -> str:
        """'as of 25s ago' (what the last known state is as of)."""
        if self.age_s is None:
            return "never heard"
        return f"as of {fmt_duration(self.age_s)} ago"

    def ago(self) -> str:
        """'25s ago' (where room is short: a column's header)."""
        return "never heard" if self.age_s is None else f"{fmt_duration(self.age_s)} ago"


FRESH = Freshness()


class Heard(Protocol):
    """What `freshness` reads of the console's model."""

    robots: dict[str, RobotInfo]
    telemetry: dict[str, Telemetry]
    heard: dict[str, datetime]


def freshness(model: Heard, robot: str, clock: MissionClock) -> Freshness:
    """How fresh the console's view of `robot` is now. Whether it is stale is
    decided in wall seconds (how often robots send); its age is said in mission time."""
    now = clock()
    info = model.robots.get(robot)
    heard = _last_heard(model.heard.get(robot), info)
    delay = _delay(info)
    away = _away(info)
    if info is not None and away:  # nothing it does now reaches the ground
        since = heard or info.since
        return Freshness(True, None if since is None else clock.span(_age(now, since, delay)), away)
    if heard is None:
        return FRESH
    age = _age(now, heard, delay)
    stale, why = _stale_why(robot in model.telemetry, age, delay)
    return Freshness(stale, clock.span(age), why)


def _delay(info: RobotInfo | None) -> float:
    """The robot's one-way delay in seconds (0 when not known)."""
    return info.delay_s if info is not None and info.delay_s is not None else 0.0


def _age(now: datetime, heard: datetime, delay: float) -> float:
    """How old, in seconds, a robot's state heard at `heard` is: it left the
    robot `delay` before it arrived."""
    return max(0.0, (now - heard).total_seconds()) + delay


def _last_heard(heard: datetime | None, info: RobotInfo | None) -> datetime | None:
    """The later of the console's own stamp and the server's."""
    if info is None or info.heard is None or (heard is not None and info.heard <= heard):
        return heard
    return info.heard


def _stale_why(sends_telemetry: bool, age: float, delay: float) -> tuple[bool, str]:
    """Silent (it was sending and stopped), delayed (too far to be live), or fresh."""
    if sends_telemetry and age - delay > SILENT_AFTER_S:
        return True, "silent"
    if delay >= SILENT_AFTER_S:
        return True, "delayed"
    return False, ""


def _away(info: RobotInfo | None) -> str:
    """'offline' (no presence), 'out of contact' (its window closed), or ''."""
    if info is not None and not info.online:
        return "offline"
    return "out of contact" if out_of_contact(info) else ""


class EtaTicks:
    """Which robots' ETA shows another second since the last look: telemetry
    comes on change, and a running skill's ETA counts down between samples
    (by the age of the robot's state, see `freshness`)."""

    def __init__(self) -> None:
        self.shown: dict[str, int] = {}  # robot -> the ETA's second at the last look

    def ticked(self, model: Any) -> set[str]:
        ticked = set()
        for robot, t in model.telemetry.items():
            if t.eta_s is None:
                continue
            shown = round(t.eta_s - (model.freshness(robot).age_s or 0.0))  # as fmt_duration
            if self.shown.setdefault(robot, shown) != shown:
                self.shown[robot] = shown
                ticked.add(robot)
        return ticked
