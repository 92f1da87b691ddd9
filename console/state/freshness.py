"""How fresh what the console knows of a robot is (no Textual here).

The ground's view of a robot is its last report: when the robot is offline,
or has stopped sending the telemetry it was sending, that view is the robot's
*last known* state, not a live one. The schedule then draws it dimmed with
"as of 25s ago", and progress and ETA stop (they are not extrapolated).

Today this is judged from what the console itself sees: presence (liveliness),
and when it last heard the robot (telemetry or a report, stamped on arrival
with the console's clock — robot clocks may differ). The robot link's state
(issue 19: one-way delay, last-heard time and pending commands per robot in
the client) extends `freshness` where marked: a robot minutes away is stale
by its delay even when its reports arrive in order, and its "as of" is the
robot's time of the report, not its arrival.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Protocol

from backend.protocol.messages import RobotInfo, Telemetry
from console.state.text import fmt_duration

# a robot that was sending telemetry and has been silent this long is stale
# (the sim sends 4 per second; a hung robot keeps its presence until its lease ends)
SILENT_AFTER_S = 10.0


@dataclass(frozen=True)
class Freshness:
    """`stale`: draw the robot's state as last known; `age_s`: since when
    (None: never heard); `why`: "offline", "silent" or "" (fresh)."""

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


def freshness(model: Heard, robot: str, now: datetime) -> Freshness:
    """How fresh the console's view of `robot` is at `now`."""
    info = model.robots.get(robot)
    heard = model.heard.get(robot)
    # (issue 19 extends here: the link's last-heard time and one-way delay)
    if info is not None and not info.online:
        since = heard or info.since
        age = max(0.0, (now - since).total_seconds()) if since is not None else None
        return Freshness(True, age, "offline")
    if heard is None:
        return FRESH
    age = max(0.0, (now - heard).total_seconds())
    if robot in model.telemetry and age > SILENT_AFTER_S:
        return Freshness(True, age, "silent")
    return Freshness(False, age, "")
