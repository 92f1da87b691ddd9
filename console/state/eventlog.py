"""The event log and the alert book — what happened, and what needs a person.

No Textual here. The console's model (console/state/model.py) feeds both
from the client's events: every operation (event batch, with the console
and user that made it), robot reports (one line per status event, rendered
from the event itself), the console's own refusals and failures, and
alerts. Both are bounded in memory: the log keeps the last `LOG_LIMIT`
entries, the alert book the last `ALERT_LIMIT` alerts (the server's journal
keeps the full history of operations).

Alerts about robots come from the server only (`backend.core.alerts`: it
numbers them, and its state snapshot repeats the last ones, so a console
that was away takes what it missed, each once). The console's own alerts
are about itself: its refusals and the messages it could not read; the same
one again within `REPEAT_WINDOW` counts up instead of piling up.
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
from backend.core.model import QuestionState, Status
from backend.protocol.messages import Alert
from console.state.text import GLYPHS, STATUS_WORDS

LOG_LIMIT = 10_000
ALERT_LIMIT = 1_000
REPEAT_WINDOW = timedelta(seconds=60)

Owner = Callable[[str], str | None]  # skill id -> its robot

Kind = Literal["operation", "report", "refusal", "failure", "alert"]
KINDS: tuple[str, ...] = ("operation", "report", "refusal", "failure", "alert")
OwnKind = Literal["refusal", "malformed"]  # what a console alerts about itself


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
    kind: str  # an AlertKind (the server's) or an OwnKind (this console's)
    robot: str | None = None
    skill: str | None = None
    message: str
    source: Literal["console", "server"] = "console"
    count: int = 1
    acknowledged: bool = False
    question: int | None = None  # a robot's question it announces (kind "question")


# -- the log ---------------------------------------------------------------------------


class EventLog:
    def __init__(self, limit: int = LOG_LIMIT) -> None:
        self.entries: deque[LogEntry] = deque(maxlen=limit)
        self.seq = 0

    def clear(self) -> None:
        self.entries.clear()
        self.seq = 0

    def add(self, kind: Kind, text: str, at: datetime, **kw: Any) -> LogEntry:
        self.seq += 1
        e = LogEntry(seq=self.seq, at=at, kind=kind, text=text, **kw)
        self.entries.append(e)
        return e

    def add_batch(self, batch: ev.EventBatch, owner: Owner, at: datetime) -> list[LogEntry]:
        """A batch (already applied: `owner` knows its skills) -> a
        report/failure line per status event of a robot's report, one
        operation line otherwise."""
        user, client = split_actor(batch.actor)
        out: list[LogEntry] = []
        if batch.op == "report":
            for e in batch.events:
                if isinstance(e, ev.SkillStatusChanged) and e.status is not None:
                    status = e.status
                    robot = owner(e.id) or client
                    info = e.info or ""
                    kind: Kind = "failure" if status == Status.FAILURE else "report"
                    text = f"{GLYPHS[status]} {e.id} {STATUS_WORDS[status]}" + (
                        f": {info}" if info else ""
                    )
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
        robots, parts = _summary(batch, owner)
        text = f"{batch.op or 'change'}" + (f": {'; '.join(parts)}" if parts else "")
        skill = next(
            (
                e.id
                for e in batch.events
                if isinstance(
                    e, ev.SkillStatusChanged | ev.SkillEdited | ev.SkillRemoved | ev.SkillMoved
                )
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
    ev.RobotAdded: lambda e: f"robot {e.name} ({e.spec.type}) joined the mission",
    ev.RobotRetired: lambda e: f"robot {e.name} retired: {e.reason}",
    ev.CommandQueued: lambda e: f"{e.command.title()} queued for {e.command.robot}",
    ev.CommandChanged: lambda e: f"command {e.id} {e.state or 'changed'}",
    ev.QuestionAsked: lambda e: (
        f"question #{e.question.id} from {e.question.robot} ({e.question.skill}): "
        f"{e.question.text} [{' / '.join(e.question.choices)}; default {e.question.default}]"
    ),
    ev.QuestionAnswered: lambda e: (
        f"question #{e.id} answered {e.choice} by {e.by or 'an operator'} (command {e.command})"
    ),
    ev.QuestionClosed: lambda e: (
        f"question #{e.id} {_closed_words(e)}" + (f" ({e.reason})" if e.reason else "")
    ),
}


CLOSED_WORDS = {
    QuestionState.ANSWERED: "answered: the robot goes on with {choice}",
    QuestionState.DEFAULTED: "defaulted: no answer in time, the robot goes on with {choice}",
}


def _closed_words(e: ev.QuestionClosed) -> str:
    """How a question ended, in the log's words."""
    return CLOSED_WORDS.get(e.state, "withdrawn").format(choice=e.choice)


EDIT_FIELDS = ("label", "params", "bindings", "policies")
# events that name their robot themselves (the others above go by skill id)
ROBOT_OF: dict[type, Callable[[Any], str | None]] = {
    ev.QuestionAsked: lambda e: e.question.robot,
}


def _no_robot(_e: Any) -> None:
    return None


def _summary(batch: ev.EventBatch, owner: Owner) -> tuple[list[str], list[str]]:
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
            case ev.SkillStatusChanged(id=sid, status=status):
                robot(owner(sid))
                parts.append(f"{sid} {status}" if status else f"{sid} status_info={e.info}")
            case ev.SkillEdited(id=sid):
                robot(owner(sid))
                ch = {k: getattr(e, k) for k in EDIT_FIELDS if getattr(e, k) is not None}
                parts.append(f"{sid} {_changes(ch)}")
            case ev.BarrierSet(id=bid, barrier=b):
                for sid in b.skills:
                    robot(owner(sid))
                parts.append(f"barrier {bid} ({', '.join(b.skills)})")
            case _:
                robot(ROBOT_OF.get(type(e), _no_robot)(e))
                phrase = PHRASES.get(type(e))
                if phrase is not None:
                    parts.append(phrase(e))
    if len(parts) > 4:
        parts = parts[:4] + [f"… {len(parts) - 4} more"]
    return robots, parts


def _changes(ch: dict[str, Any]) -> str:
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
        self._seen: set[tuple[str, int]] = set()  # (server run, alert id) taken already

    def clear(self) -> None:
        self.alerts.clear()
        self._seen.clear()
        self.next_id = 1

    @property
    def unacknowledged(self) -> int:
        return sum(1 for a in self.alerts if not a.acknowledged)

    def _append(self, **fields: Any) -> AlertEntry:
        a = AlertEntry(id=self.next_id, **fields)
        self.next_id += 1
        self.alerts.append(a)
        return a

    def add(
        self,
        kind: OwnKind,
        message: str,
        at: datetime,
        *,
        robot: str | None = None,
        skill: str | None = None,
    ) -> AlertEntry | None:
        """This console's own alert; None when the same one was raised within
        REPEAT_WINDOW (it counts up instead)."""
        for a in reversed(self.alerts):
            same = (a.source, a.kind, a.robot, a.skill, a.message) == (
                "console",
                kind,
                robot,
                skill,
                message,
            )
            if same and abs(a.at - at) <= REPEAT_WINDOW:
                a.count += 1
                return None
        return self._append(at=at, kind=kind, robot=robot, skill=skill, message=message)

    def from_server(self, a: Alert, server: str) -> AlertEntry | None:
        """The server's alert (run `server`); None when taken already."""
        if (server, a.id) in self._seen:
            return None
        self._seen.add((server, a.id))
        return self._append(
            at=a.at,
            level=a.level,
            kind=a.kind.value,
            robot=a.robot,
            skill=a.skill,
            message=a.message,
            source="server",
            question=a.question,
        )

    def seen(self, alerts: Iterable[Alert], server: str) -> None:
        """Alerts raised before this console first looked: not news."""
        self._seen.update((server, a.id) for a in alerts)

    def acknowledge(self, alert_id: int | None = None) -> int:
        """One alert (by id) or all (None); returns how many changed."""
        n = 0
        for a in self.alerts:
            if not a.acknowledged and (alert_id is None or a.id == alert_id):
                a.acknowledged = True
                n += 1
        return n


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
