"""The event log and the alert book — what happened, and what needs a person.

No Textual here. The app feeds both from its messages: every operation
(event batch, with the console and user that made it), robot reports (status
changes), the console's own refusals, failures, and alerts. Both are bounded
in memory: the log keeps the last `LOG_LIMIT` entries, the alert book the last
`ALERT_LIMIT` alerts; older ones are dropped (the server's journal keeps the
full history of operations).

Alerts come from two sides: the console derives what it can see itself
(failures in reports, robots going offline, out of range, low battery, its
own refusals) and the server publishes `Alert`s (failures, offline, ...).
The same situation reported by both is one alert: alerts with the same
(kind, robot, skill, text key) within `MERGE_WINDOW` are merged.
"""

from __future__ import annotations

import json
from collections import deque
from collections.abc import Callable, Iterable
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel

from backend.core import events as ev
from backend.core.model import Mission
from backend.protocol.messages import Alert, RobotInfo, Telemetry
from console.state.model import ConsoleModel
from console.state.text import GLYPHS, STATUS_WORDS

LOG_LIMIT = 10_000
ALERT_LIMIT = 1_000
MERGE_WINDOW = timedelta(seconds=60)
LOW_BATTERY = 0.20

Kind = Literal["operation", "report", "refusal", "failure", "alert"]
KINDS: tuple[str, ...] = ("operation", "report", "refusal", "failure", "alert")
AlertKind = Literal[
    "failure", "offline", "out_of_range", "low_battery", "refusal", "server", "malformed"
]


def split_actor(actor: str) -> tuple[str, str]:
    """(user, client) from an EventBatch actor: the server writes 'user@client'
    when the request named a user, else the client id (a robot for reports).
    Client ids never contain '@' (host-pid-hex), a user may: split at the last."""
    user, at, client = actor.rpartition("@")
    return (user, client) if at else ("", actor)


class LogEntry(BaseModel):
    """One line of the event log (one JSON object per line when exported)."""

    seq: int
    at: datetime
    kind: Kind
    robots: list[str] = []
    skill: str | None = None
    client: str = ""
    user: str = ""
    op: str = ""
    revision: int | None = None
    text: str


class AlertEntry(BaseModel):
    id: int
    at: datetime
    level: Literal["info", "warning", "error"] = "warning"
    kind: AlertKind
    robot: str | None = None
    skill: str | None = None
    message: str
    source: Literal["console", "server", "both"] = "console"
    count: int = 1
    acknowledged: bool = False


# -- the log ---------------------------------------------------------------------------


class EventLog:
    def __init__(self, limit: int = LOG_LIMIT) -> None:
        self.entries: deque[LogEntry] = deque(maxlen=limit)
        self.seq = 0

    def add(self, kind: str, text: str, at: datetime, **kw) -> LogEntry:
        self.seq += 1
        e = LogEntry(seq=self.seq, at=at, kind=kind, text=text, **kw)
        self.entries.append(e)
        return e

    def add_batch(self, batch: ev.EventBatch, model: ConsoleModel, at: datetime) -> list[LogEntry]:
        """A batch already applied to `model` -> a report/failure line per status
        change for robot reports, one operation line otherwise."""
        user, client = split_actor(batch.actor)
        out: list[LogEntry] = []
        if batch.op == "report":
            for e in batch.events:
                if isinstance(e, ev.SkillChanged) and "status" in e.changes:
                    status = e.changes["status"]
                    robot = model.owner(e.id) or client
                    info = e.changes.get("status_info") or ""
                    word = next(
                        (STATUS_WORDS[s] for s in STATUS_WORDS if s.value == status), status
                    )
                    glyph = next((GLYPHS[s] for s in GLYPHS if s.value == status), "·")
                    kind = "failure" if status == "failure" else "report"
                    text = f"{glyph} {e.id} {word}" + (f": {info}" if info else "")
                    out.append(
                        self.add(
                            kind,
                            text,
                            at,
                            robots=[robot],
                            skill=e.id,
                            client=client,
                            user=user,
                            op=batch.op,
                            revision=batch.revision,
                        )
                    )
            return out
        robots, parts = _summary(batch, model)
        text = f"{batch.op or 'change'}" + (f": {'; '.join(parts)}" if parts else "")
        skill = next(
            (
                e.id
                for e in batch.events
                if isinstance(e, ev.SkillChanged | ev.SkillRemoved | ev.SkillMoved)
            ),
            None,
        )
        out.append(
            self.add(
                "operation",
                text,
                at,
                robots=robots,
                skill=skill,
                client=client,
                user=user,
                op=batch.op,
                revision=batch.revision,
            )
        )
        return out

    def select(self, query: str) -> list[LogEntry]:
        return [e for e in self.entries if entry_matches(e, query)]

    def export(self, path: Path, entries: Iterable[LogEntry] | None = None) -> int:
        """Write JSON lines (one LogEntry each); returns how many."""
        rows = list(self.entries if entries is None else entries)
        with path.open("w", encoding="utf-8") as f:
            for e in rows:
                f.write(e.model_dump_json() + "\n")
        return len(rows)


def read_jsonl(path: Path) -> list[LogEntry]:
    return [
        LogEntry.model_validate(json.loads(line))
        for line in path.read_text(encoding="utf-8").splitlines()
        if line.strip()
    ]


# events that touch no robot's column -> their phrase in an operation's log line
PHRASES: dict[type, Callable[[Any], str]] = {
    ev.BarrierRemoved: lambda e: f"barrier {e.id} removed",
    ev.MarkerSet: lambda e: f"marker {e.name}",
    ev.MarkerRemoved: lambda e: f"marker {e.name} removed",
    ev.MissionReplaced: lambda e: f"mission replaced by '{e.mission.name}'",
    ev.WaiverSet: lambda e: f"waived {e.check}: {e.waiver.reason}",
    ev.WaiverRemoved: lambda e: f"waiver of {e.check} withdrawn",
    ev.CommandQueued: lambda e: f"{e.command.title()} queued for {e.command.robot}",
    ev.CommandChanged: lambda e: f"command {e.id} {e.changes.get('state', 'changed')}",
}


def _summary(batch: ev.EventBatch, model: ConsoleModel) -> tuple[list[str], list[str]]:
    robots: list[str] = []
    parts: list[str] = []

    def robot(r: str | None) -> None:
        if r and r not in robots:
            robots.append(r)

    for e in batch.events:
        match e:
            case ev.SkillAdded(robot=r, skill=s):
                robot(r)
                parts.append(f"+{s.id} ({s.skill})")
            case ev.SkillRemoved(robot=r, id=sid):
                robot(r)
                parts.append(f"-{sid}")
            case ev.SkillMoved(robot=r, id=sid, index=i):
                robot(r)
                parts.append(f"{sid} → #{i + 1}")
            case ev.SkillChanged(id=sid, changes=ch):
                robot(model.owner(sid))
                status = ch.get("status")
                parts.append(f"{sid} {status}" if status else f"{sid} {_changes(ch)}")
            case ev.BarrierSet(id=bid, barrier=b):
                for sid in b.skills:
                    robot(model.owner(sid))
                parts.append(f"barrier {bid} ({', '.join(b.skills)})")
            case _:
                phrase = PHRASES.get(type(e))
                if phrase is not None:
                    parts.append(phrase(e))
    if len(parts) > 4:
        parts = parts[:4] + [f"… {len(parts) - 4} more"]
    return robots, parts


def _changes(ch: dict) -> str:
    """'label=find a stone, params' — short values shown, the rest named."""
    out = []
    for k in sorted(ch):
        v = ch[k]
        out.append(f"{k}={v}" if isinstance(v, str | int | float) and len(str(v)) <= 30 else k)
    return ", ".join(out)


def entry_matches(e: LogEntry, query: str) -> bool:
    """`robot:lru1 kind:failure words…` — every part must match."""
    for word in query.lower().split():
        field, sep, value = word.partition(":")
        if sep and field == "robot":
            if not any(value in r.lower() for r in e.robots):
                return False
        elif sep and field == "kind":
            if not e.kind.startswith(value):
                return False
        else:
            hay = " ".join(
                [e.text, e.kind, *e.robots, e.skill or "", e.client, e.user, e.op]
            ).lower()
            if word not in hay:
                return False
    return True


# -- alerts ---------------------------------------------------------------------------------


class AlertBook:
    def __init__(self, limit: int = ALERT_LIMIT) -> None:
        self.alerts: deque[AlertEntry] = deque(maxlen=limit)
        self.next_id = 1
        # per robot: last known presence, range, battery side of the threshold
        self._online: dict[str, bool] = {}
        self._in_range: dict[str, bool] = {}
        self._low: dict[str, bool] = {}

    @property
    def unacknowledged(self) -> int:
        return sum(1 for a in self.alerts if not a.acknowledged)

    def add(
        self,
        kind: str,
        message: str,
        at: datetime,
        *,
        level: str = "warning",
        robot: str | None = None,
        skill: str | None = None,
        source: str = "console",
    ) -> AlertEntry | None:
        """A new alert, or None when it merged into an alert of the same situation."""
        for a in reversed(self.alerts):
            if (
                a.kind == kind
                and a.robot == robot
                and a.skill == skill
                and abs(a.at - at) <= MERGE_WINDOW
            ):
                if kind == "refusal" and a.message != message:
                    continue
                if a.source != source:
                    a.source = "both"
                    if source == "server" and len(message) > len(a.message):
                        a.message = message  # the server's sentence may say more
                else:
                    a.count += 1
                return None
        a = AlertEntry(
            id=self.next_id,
            at=at,
            level=level,
            kind=kind,
            robot=robot,
            skill=skill,
            message=message,
            source=source,
        )
        self.next_id += 1
        self.alerts.append(a)
        return a

    def acknowledge(self, alert_id: int | None = None) -> int:
        """One alert (by id) or all (None); returns how many changed."""
        n = 0
        for a in self.alerts:
            if not a.acknowledged and (alert_id is None or a.id == alert_id):
                a.acknowledged = True
                n += 1
        return n

    # -- what the console derives itself ------------------------------------------------
    def from_server(self, a: Alert) -> AlertEntry | None:
        kind = {"failure": "failure", "offline": "offline"}.get(
            getattr(a, "kind", "") or "", "server"
        )
        return self.add(
            kind, a.message, a.at, level=a.level, robot=a.robot, skill=a.skill, source="server"
        )

    def from_batch(self, entries: list[LogEntry]) -> list[AlertEntry]:
        out = []
        for e in entries:
            if e.kind == "failure":
                robot = e.robots[0] if e.robots else None
                a = self.add(
                    "failure",
                    f"{robot}: {e.text.removeprefix('✗ ')}",
                    e.at,
                    level="error",
                    robot=robot,
                    skill=e.skill,
                )
                if a:
                    out.append(a)
        return out

    def from_fleet(self, info: RobotInfo, at: datetime) -> AlertEntry | None:
        was = self._online.get(info.name)
        self._online[info.name] = info.online
        if was and not info.online:
            return self.add(
                "offline", f"robot {info.name} went offline", info.since or at, robot=info.name
            )
        return None

    def from_telemetry(self, t: Telemetry, at: datetime) -> list[AlertEntry]:
        out = []
        r = t.robot
        was_in = self._in_range.get(r, True)
        self._in_range[r] = t.in_range
        if was_in and not t.in_range:
            a = self.add("out_of_range", f"{r} is out of communication range", at, robot=r)
            if a:
                out.append(a)
        low = t.battery < LOW_BATTERY
        was_low = self._low.get(r, False)
        self._low[r] = low
        if low and not was_low:  # once per crossing; re-armed when back above
            a = self.add(
                "low_battery",
                f"{r}: battery low ({int(t.battery * 100)} % < {int(LOW_BATTERY * 100)} %)",
                at,
                robot=r,
            )
            if a:
                out.append(a)
        return out

    def seed_fleet(
        self, robots: dict[str, RobotInfo], at: datetime | None = None
    ) -> list[AlertEntry]:
        """A full state: remember presence. On the first one nothing is a
        change; after a reconnect (`at` given) a robot seen online before and
        offline now went offline while the console was away: an alert."""
        out = []
        for name, info in robots.items():
            was = self._online.get(name)
            self._online[name] = info.online
            if at is not None and was and not info.online:
                a = self.add("offline", f"robot {name} went offline", info.since or at, robot=name)
                if a:
                    out.append(a)
        return out

    def missed_failures(
        self, before: dict[str, str], mission: Mission, at: datetime
    ) -> list[AlertEntry]:
        """After a reconnect: skills that failed while the console was away
        (`before`: skill id -> status it last knew)."""
        out = []
        for robot, task in mission.tasks.items():
            for s in task:
                if s.status.value == "failure" and before.get(s.id) != "failure":
                    text = (
                        f"{robot}: {s.id} failure: {s.status_info}"
                        if s.status_info
                        else f"{robot}: {s.id} failed"
                    )
                    a = self.add(
                        "failure", text, s.finished_at or at, level="error", robot=robot, skill=s.id
                    )
                    if a:
                        out.append(a)
        return out


TOAST_TOGETHER = timedelta(seconds=30)  # offline alerts this close are one situation


def toast_text(book: AlertBook, a: AlertEntry) -> tuple[str, str]:
    """(title, message) of the notification for alert `a`: robots going
    offline together (the link, the sim or the site went down) are one
    notification naming them all, each later one replacing it."""
    if a.kind == "offline" and a.robot:
        robots = list(
            dict.fromkeys(
                x.robot
                for x in book.alerts
                if x.kind == "offline"
                and x.robot
                and not x.acknowledged
                and abs(x.at - a.at) <= TOAST_TOGETHER
            )
        )
        if len(robots) > 1:
            names = ", ".join(robots[:-1]) + f" and {robots[-1]}"
            return "Robots offline", f"{names} went offline"
        return "Robots offline", a.message
    return " · ".join(x for x in (a.robot, a.skill) if x) or "Alert", a.message
