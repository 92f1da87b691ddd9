"""Verifying each command on the server: its stages and their dues, published on
`RobotInfo.verification`; an overdue stage raises an alert (the computing:
backend.core.verification).

The forecast a client sends with a sync (`Sync.forecast`) is kept here while
its skills are under way: it times the started and completed stages. After a
restart it is read back from the journaled syncs (`resume`).

A stage's due moves a little with every estimate of the delay and every
status of the simulator (its clock): a robot's list is published again when
a stage's state changes or a due moves by more than `MOVED_S`.
"""

from __future__ import annotations

from collections.abc import Callable
from datetime import datetime
from itertools import chain
from typing import Any, Final

from backend.core.alerts import AlertKind, Raises
from backend.core.model import Mission
from backend.core.ops import Predicted, Sync
from backend.core.verification import (
    Path,
    Stage,
    Verification,
    late_s,
    under_way,
    verify,
    watched,
)
from backend.protocol.messages import MissionClock, RobotInfo
from backend.server.contact import ContactWatch

MOVED_S: Final = 1.0
MAX_VERIFIED: Final = 200  # per robot, the oldest first (a protocol limit of RobotInfo)


class VerificationWatch:
    def __init__(self, host: Raises, contact: ContactWatch) -> None:
        self.host = host
        self.contact = contact
        self.forecasts: dict[str, Predicted] = {}  # skill id -> as synchronized
        self.lists: dict[str, list[Verification]] = {}  # robot -> its commands under way
        self._alerted: set[tuple[int, str]] = set()  # (command, stage) said overdue

    def applied(self, op: Any) -> None:
        """An operation was applied: a sync's forecast is kept."""
        if isinstance(op, Sync):
            self.forecasts.update(op.forecast)

    def resume(
        self, mission: Mission, forecasts: Callable[[set[str]], dict[str, Predicted]]
    ) -> None:
        """After a restart: `forecasts(skills)` (the journal's) for the skills
        of the commands still under way."""
        going = [c for cmds in mission.uplink.values() for c in cmds if under_way(c, mission)]
        self.forecasts.update(forecasts({s for c in going for s in watched(c)}))

    def of(self, robot: str) -> list[Verification]:
        return self.lists.get(robot, [])

    def path(self, info: RobotInfo | None) -> Path:
        if info is None:
            return Path(open_from=lambda _t: None)
        name, online = info.name, info.online
        return Path(
            delay_s=info.delay_s or 0.0,
            open_from=lambda t: self.contact.open_from(name, online, t),
        )

    def refresh(self, mission: Mission, robots: dict[str, RobotInfo], now: datetime) -> list[str]:
        """Every command under way verified at `now`; overdue stages alerted.
        Returns the robots whose list changed (to publish)."""
        changed = [r for r in self.lists if r not in mission.uplink]
        for robot in changed:
            del self.lists[robot]
        for robot in mission.uplink:
            if self._robot(mission, robots.get(robot), robot, now):
                changed.append(robot)
        self._forget()
        return changed

    def _forget(self) -> None:
        """The forecasts of skills no longer under way."""
        kept = {s for v in chain.from_iterable(self.lists.values()) for s in v.skills}
        self.forecasts = {s: self.forecasts[s] for s in kept & self.forecasts.keys()}

    def _robot(self, mission: Mission, info: RobotInfo | None, robot: str, now: datetime) -> bool:
        """One robot's commands verified; whether its list changed."""
        path = self.path(info)
        going = [c for c in mission.uplink[robot] if under_way(c, mission)][-MAX_VERIFIED:]
        new = [verify(c, mission, path, self.forecasts, now) for c in going]
        for v in new:
            self._alert(v, info, now)
        moved = _moved(self.lists.get(robot, []), new)
        self.lists[robot] = new
        return moved

    def _alert(self, v: Verification, info: RobotInfo | None, now: datetime) -> None:
        stage = self._new_overdue(v)
        if stage is None or stage.due is None:
            return
        clock: MissionClock = "sim" if self.contact.mirror.status is not None else "wall"
        late = late_s(stage, now) * self.contact.speed(clock)
        self.host.alert(
            f"{_what(v, stage)}: due {self.contact.time_text(stage.due)}, "
            f"{span_text(late)} late{self._context(v.robot, info)}",
            kind=AlertKind.OVERDUE,
            robot=v.robot,
            skill=v.skills[0] if stage.name in ("started", "completed") and v.skills else None,
            command=v.command,
        )

    def _new_overdue(self, v: Verification) -> Stage | None:
        """Its current stage if it is overdue and was not said yet."""
        stage = v.current
        key = (v.command, stage.name if stage is not None else "")
        if stage is None or stage.state != "overdue" or key in self._alerted:
            return None
        self._alerted.add(key)
        return stage

    def _context(self, robot: str, info: RobotInfo | None) -> str:
        """What the ground knows of the robot's link: why it may be late."""
        state = info.contact.state if info is not None and info.contact else "offline"
        if state != "in_contact" or info is None or info.heard is None:
            return f"; {robot} is {state.replace('_', ' ')}"
        return f"; {robot} last heard {self.contact.time_text(info.heard)}"


def _what(v: Verification, stage: Stage) -> str:
    """The stage not reached, in words: 'lru1-4 has not started (command 17)'."""
    title = f"command {v.command} ({v.op}{' ' + ', '.join(v.skills) if v.skills else ''})"
    if stage.name in _UPLINK_WORDS:
        return f"{title} {_UPLINK_WORDS[stage.name]} {v.robot}"
    names = ", ".join(v.skills) if len(v.skills) <= 3 else f"{v.skills[0]}..{v.skills[-1]}"
    verb = "has" if len(v.skills) == 1 else "have"
    return f"{names} {verb} not {stage.name} (command {v.command})"


_UPLINK_WORDS = {"sent": "has no receipt from", "received": "has not been received by"}


def span_text(seconds: float) -> str:
    """A mission duration for a sentence: '40 s', '6 min', '2 h 05 min'."""
    s = int(round(seconds))
    if s < 90:
        return f"{s} s"
    if s < 90 * 60:
        return f"{round(s / 60)} min"
    return f"{s // 3600} h {(s % 3600) // 60:02d} min"


def _states(vs: list[Verification]) -> list[tuple[int, list[str]]]:
    return [(v.command, [s.state for s in v.stages]) for v in vs]


def _moved(old: list[Verification], new: list[Verification]) -> bool:
    if _states(old) != _states(new):
        return True
    pairs = (zip(x.stages, y.stages, strict=True) for x, y in zip(old, new, strict=True))
    return any(_due_moved(a.due, b.due) for stages in pairs for a, b in stages)


def _due_moved(a: datetime | None, b: datetime | None) -> bool:
    if a is None or b is None:
        return (a is None) != (b is None)
    return abs((a - b).total_seconds()) > MOVED_S
