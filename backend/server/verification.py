"""Verifying each command on the server: its stages and their dues, published on
`RobotInfo.verification`; an overdue stage raises an alert (the computing:
backend.core.verification).

The forecast a client sends with a sync (`Sync.forecast`) is kept here while
its skills are under way: it times the started and completed stages. It
lives in memory: after a restart a command's skills have no due until they
are synchronized again (their earlier stages still have theirs).

A stage's due moves a little with every estimate of the delay and every
status of the simulator (its clock): a robot's list is published again when
a stage's state changes or a due moves by more than `MOVED_S`.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any, Final

from backend.core.alerts import AlertKind, Raises
from backend.core.model import Mission
from backend.core.ops import Predicted, Sync
from backend.core.verification import Path, Stage, Verification, late_s, under_way, verify
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
        changed: list[str] = []
        kept: set[str] = set()
        for robot, cmds in mission.uplink.items():
            path = self.path(robots.get(robot))
            going = [c for c in cmds if under_way(c, mission)][-MAX_VERIFIED:]
            new = [verify(c, mission, path, self.forecasts, now) for c in going]
            for v in new:
                kept.update(v.skills)
                self._alert(v, robots.get(robot), now)
            if _moved(self.lists.get(robot, []), new):
                changed.append(robot)
            self.lists[robot] = new
        for robot in [r for r in self.lists if r not in mission.uplink]:
            del self.lists[robot]
            changed.append(robot)
        self.forecasts = {s: p for s, p in self.forecasts.items() if s in kept}
        return changed

    def _alert(self, v: Verification, info: RobotInfo | None, now: datetime) -> None:
        stage = v.current
        if stage is None or stage.state != "overdue" or (v.command, stage.name) in self._alerted:
            return
        self._alerted.add((v.command, stage.name))
        assert stage.due is not None
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

    def _context(self, robot: str, info: RobotInfo | None) -> str:
        """What the ground knows of the robot's link: why it may be late."""
        if info is None or not info.online:
            return f"; {robot} is offline"
        c = info.contact
        if c is not None and c.state == "out_of_contact":
            return f"; {robot} is out of contact"
        heard = f"; {robot} last heard {self.contact.time_text(info.heard)}" if info.heard else ""
        return heard


def _what(v: Verification, stage: Stage) -> str:
    """The stage not reached, in words: 'lru1-4 has not started (command 17)'."""
    title = f"command {v.command} ({v.op}{' ' + ', '.join(v.skills) if v.skills else ''})"
    if stage.name == "sent":
        return f"{title} has not left for {v.robot} (no receipt)"
    if stage.name == "received":
        return f"{title} has not been received by {v.robot}"
    names = ", ".join(v.skills) if len(v.skills) <= 3 else f"{v.skills[0]}..{v.skills[-1]}"
    verb = "has" if len(v.skills) == 1 else "have"
    return f"{names} {verb} not {stage.name} (command {v.command})"


def span_text(seconds: float) -> str:
    """A mission duration for a sentence: '40 s', '6 min', '2 h 05 min'."""
    s = int(round(seconds))
    if s < 90:
        return f"{s} s"
    if s < 90 * 60:
        return f"{round(s / 60)} min"
    return f"{s // 3600} h {(s % 3600) // 60:02d} min"


def _moved(old: list[Verification], new: list[Verification]) -> bool:
    if [(v.command, [s.state for s in v.stages]) for v in old] != [
        (v.command, [s.state for s in v.stages]) for v in new
    ]:
        return True
    return any(
        _due_moved(a.due, b.due)
        for x, y in zip(old, new, strict=True)
        for a, b in zip(x.stages, y.stages, strict=True)
    )


def _due_moved(a: datetime | None, b: datetime | None) -> bool:
    if a is None or b is None:
        return (a is None) != (b is None)
    return abs((a - b).total_seconds()) > MOVED_S
