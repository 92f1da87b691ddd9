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

import functools
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
        if batch.op == "report":
            return self._reports(batch, owner, at, user, client)
        robots, parts = _summary(batch, owner)
        text = f"{batch.op or 'change'}" + (f": {'; '.join(parts)}" if parts else "")
        return [
            self.add(
                "operation",
                text,
                at,
                robots=robots,
                skill=_first_skill(batch),
                client=client,
                user=user,
                op=batch.op,
                revision=batch.revision,
            )
        ]

    def _reports(
        self, batch: ev.EventBatch, owner: Owner, at: datetime, user: str, client: str
    ) -> list[LogEntry]:
        """A robot's report: a report (or failure) line per status it sets."""
        return [
            self.add(
                "failure" if e.status == Status.FAILURE else "report",
                report_text(e.status, e.id, e.info),
                at,
                robots=[owner(e.id) or client],
                skill=e.id,
                client=client,
                user=user,
                op=batch.op,
                revision=batch.revision,
            )
            for e in batch.events
            if isinstance(e, ev.SkillStatusChanged) and e.status is not None
        ]

    def select(self, query: str) -> list[LogEntry]:
        return [e for e in self.entries if entry_matches(e, query)]

    def export(self, path: Path, entries: Iterable[LogEntry] | None = None) -> int:
        """Write JSON lines (one LogEntry each); returns how many."""
        rows = list(self.entries if entries is None else entries)
        with path.open("w", encoding="utf-8") as f:
            for e in rows:
                f.write(e.model_dump_json() + "\n")
        return len(rows)


def report_text(status: Status, skill: str, info: str | None) -> str:
    """A robot's report of a skill's new status, as its log line says it."""
    return f"{GLYPHS[status]} {skill} {STATUS_WORDS[status]}" + (f": {info}" if info else "")


def _first_skill(batch: ev.EventBatch) -> str | None:
    """The skill an operation is about: the first one an event names by id."""
    return next((e.id for e in batch.events if isinstance(e, _NAMES_A_SKILL)), None)


_NAMES_A_SKILL = (ev.SkillStatusChanged, ev.SkillEdited, ev.SkillRemoved, ev.SkillMoved)


def read_jsonl(path: Path) -> list[LogEntry]:
    return [
        LogEntry.model_validate(json.loads(line))
        for line in path.read_text(encoding="utf-8").splitlines()
        if line.strip()
    ]


# each event -> its phrase in an operation's log line
PHRASES: dict[type, Callable[[Any], str]] = {
    ev.SkillAdded: lambda e: f"+{e.skill.id} ({e.skill.skill})",
    ev.SkillRemoved: lambda e: f"-{e.id}",
    ev.SkillMoved: lambda e: f"{e.id} → #{e.index + 1}",
    ev.SkillStatusChanged: lambda e: (
        f"{e.id} {e.status}" if e.status else f"{e.id} status_info={e.info}"
    ),
    ev.SkillEdited: lambda e: f"{e.id} {_changes(_edited(e))}",
    ev.BarrierSet: lambda e: f"barrier {e.id} ({', '.join(e.barrier.skills)})",
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


def _edited(e: ev.SkillEdited) -> dict[str, Any]:
    """The fields an edit sets, by name."""
    return {k: getattr(e, k) for k in EDIT_FIELDS if getattr(e, k) is not None}


# each event -> the robots whose columns it touches (a skill's, by its id: `owner`)
ROBOTS_OF: dict[type, Callable[[Any, Owner], Iterable[str | None]]] = {
    ev.SkillAdded: lambda e, owner: (e.robot,),
    ev.SkillRemoved: lambda e, owner: (e.robot,),
    ev.SkillMoved: lambda e, owner: (e.robot,),
    ev.SkillStatusChanged: lambda e, owner: (owner(e.id),),
    ev.SkillEdited: lambda e, owner: (owner(e.id),),
    ev.BarrierSet: lambda e, owner: map(owner, e.barrier.skills),
    ev.QuestionAsked: lambda e, owner: (e.question.robot,),
}


def _no_robot(_e: Any, _owner: Owner) -> tuple[()]:
    return ()


def _summary(batch: ev.EventBatch, owner: Owner) -> tuple[list[str], list[str]]:
    """The robots an operation touches (in the order it names them) and its
    phrases, the fifth and later counted."""
    robots: dict[str, None] = {}
    parts: list[str] = []
    for e in batch.events:
        robots.update((r, None) for r in ROBOTS_OF.get(type(e), _no_robot)(e, owner) if r)
        phrase = PHRASES.get(type(e))
        if phrase is not None:
            parts.append(phrase(e))
    if len(parts) > 4:
        parts = parts[:4] + [f"… {len(parts) - 4} more"]
    return list(robots), parts


def _changes(ch: dict[str, Any]) -> str:
    """'label=find a stone, params' — short values shown, the rest named."""
    out = []
    for k in sorted(ch):
        v = ch[k]
        out.append(f"{k}={v}" if isinstance(v, str | int | float) and len(str(v)) <= 30 else k)
    return ", ".join(out)


def entry_matches(e: LogEntry, query: str) -> bool:
    """`robot:lru1 kind:failure words…` — every part must match."""
    for test, value in _query_parts(query):  # (a loop: all() over a generator is slower)
        if not test(e, value):
            return False
    return True


def _has_word(e: LogEntry, word: str) -> bool:
    hay = " ".join([e.text, e.kind, *e.robots, e.skill or "", e.client, e.user, e.op])
    return word in hay.lower()


# a query's `field:value` parts, by field (any other word is looked for in the entry)
FIELD_MATCHES: dict[str, Callable[[LogEntry, str], bool]] = {
    "robot": lambda e, value: any(value in r.lower() for r in e.robots),
    "kind": lambda e, value: e.kind.startswith(value),
}


@functools.lru_cache(maxsize=16)
def _query_parts(query: str) -> tuple[tuple[Callable[[LogEntry, str], bool], str], ...]:
    """A query as (test, value) per word, read once for all the entries it filters."""
    parts = []
    for word in query.lower().split():
        field, sep, value = word.partition(":")
        test = FIELD_MATCHES.get(field) if sep else None
        parts.append((test, value) if test is not None else (_has_word, word))
    return tuple(parts)


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
    if a.kind != "offline" or not a.robot:
        return " · ".join(x for x in (a.robot, a.skill) if x) or "Alert", a.message
    robots = _offline_with(book, a)
    if len(robots) > 1:
        names = ", ".join(robots[:-1]) + f" and {robots[-1]}"
        return "Robots offline", f"{names} went offline"
    return "Robots offline", a.message


def _offline_with(book: AlertBook, a: AlertEntry) -> list[str]:
    """The robots of the unacknowledged offline alerts within TOAST_TOGETHER
    of `a` (its own included), each once, oldest first."""
    return list(
        dict.fromkeys(
            x.robot
            for x in book.alerts
            if x.kind == "offline"
            and x.robot
            and not x.acknowledged
            and abs(x.at - a.at) <= TOAST_TOGETHER
        )
    )
