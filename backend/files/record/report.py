"""Plan against actual: what a recorded mission planned and what happened.

One pass over the journal (`JournalReader`), from its oldest snapshot:

- per skill: its robot, skill and label; the start and end its forecast
  had when it was last synchronized (the `forecast` a client sent with the
  sync; none when the client sent none); when it actually started and
  ended by the robot's clock (its reports' own times); how it ended, its
  failures, and the attempt that retried it;
- waivers (which check, why, who, when, withdrawn);
- refusals (commands a robot refused, robot messages the server refused);
- overdue verifications: empty, named — verification stages (issue 34)
  do not exist yet;
- who did what: each actor's operations by kind.

Skills deleted before they were ever synchronized are counted, not listed.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from datetime import UTC, datetime
from typing import Any

from pydantic import BaseModel, Field

from backend.core import events as ev
from backend.core.model import CommandState, Mission, SkillInstance, Status
from backend.files.record.journal import Batch, JournalReader

WALL_NOTE = (
    "wall time (local) throughout, lateness in wall seconds: the journal records no "
    "simulator's mission clock (a simulated mission's sim times cannot be shown)"
)
OVERDUE_NOTE = (
    "verification stages of commands (queued, sent, received, started, completed, each "
    "with a due time) do not exist yet; this section lists the overdue ones once they do"
)


def _t(seconds: float) -> datetime:
    return datetime.fromtimestamp(seconds, UTC)


class SkillRow(BaseModel):
    id: str
    robot: str
    skill: str
    label: str = ""
    attempt: int = 1
    status: Status = Status.IDLE
    synchronized: datetime | None = Field(None, description="ground time of its last sync")
    synchronized_by: str = ""
    predicted_start: datetime | None = None
    predicted_end: datetime | None = None
    started: datetime | None = Field(None, description="robot time")
    finished: datetime | None = Field(None, description="robot time")
    failures: list[str] = Field(default_factory=list)
    retry_of: str | None = None
    retried_as: str | None = None

    @property
    def start_late_s(self) -> float | None:
        return _late(self.predicted_start, self.started)

    @property
    def end_late_s(self) -> float | None:
        return _late(self.predicted_end, self.finished)


def _late(planned: datetime | None, actual: datetime | None) -> float | None:
    if planned is None or actual is None:
        return None
    return (actual - planned).total_seconds()


class WaiverRow(BaseModel):
    check: str
    reason: str
    by: str
    at: datetime
    withdrawn: datetime | None = None


class RefusalRow(BaseModel):
    at: datetime
    robot: str
    what: str
    reason: str


class ActorRow(BaseModel):
    actor: str
    operations: dict[str, int]


class PlanReport(BaseModel):
    journal: str
    mission: str
    start: datetime | None
    end: datetime | None
    changes: int
    gap: str = Field("", description="what the journal cannot show (written by an older server)")
    skills: list[SkillRow]
    deleted_unsynchronized: int = 0
    unsynchronized_at_end: int = 0
    waivers: list[WaiverRow]
    refusals: list[RefusalRow]
    overdue: list[dict[str, str]] = Field(default_factory=list)
    overdue_note: str = OVERDUE_NOTE
    actors: list[ActorRow]


class _Pass:
    """What the pass keeps while it reads the batches, from the mission it starts at."""

    def __init__(self, base: Mission) -> None:
        self.rows: dict[str, SkillRow] = {}
        self.synced: set[str] = set()
        self.deleted = 0
        self.mission = base.name
        self.waivers: dict[str, WaiverRow] = {}
        self.waiver_log: list[WaiverRow] = []
        self.refusals: list[RefusalRow] = []
        self.commands: dict[int, tuple[str, str]] = {}  # id -> (robot, title)
        self.actors: dict[str, Counter[str]] = {}
        self._add_tasks(base)

    def add(self, robot: str, s: SkillInstance) -> None:
        row = SkillRow(
            id=s.id, robot=robot, skill=s.skill, label=s.label, attempt=s.attempt, status=s.status
        )
        row.started, row.finished = s.started_at, s.finished_at
        if s.attempt > 1:
            base = s.id.split(".")[0]
            row.retry_of = base if s.attempt == 2 else f"{base}.{s.attempt - 1}"
            before = self.rows.get(row.retry_of)
            if before is not None:
                before.retried_as = s.id
        if s.status != Status.IDLE:
            self.synced.add(s.id)
        self.rows[s.id] = row

    def _add_tasks(self, m: Mission) -> None:
        for robot, task in m.tasks.items():
            for s in task:
                self.add(robot, s)

    def batch(self, b: Batch) -> None:
        self.actors.setdefault(b.actor or b.client or "?", Counter())[b.name] += 1
        read = _ON_OP.get(b.name)
        if read is not None:
            read(self, b)
        for e in b.batch.events:
            on = _ON_EVENT.get(type(e))
            if on is not None:
                on(self, b, e)

    def _sync(self, b: Batch) -> None:
        forecast = b.op.get("forecast")
        if not isinstance(forecast, dict):
            return
        for sid, p in forecast.items():
            row = self.rows.get(sid)
            if row is None or not isinstance(p, dict):
                continue
            try:
                row.predicted_start = datetime.fromisoformat(str(p["start"]))
                row.predicted_end = datetime.fromisoformat(str(p["end"]))
            except (KeyError, ValueError):
                continue
            row.synchronized, row.synchronized_by = _t(b.ts), b.actor

    def _downlink_refused(self, b: Batch) -> None:
        op = b.op
        self.refusals.append(
            RefusalRow(
                at=_t(b.ts),
                robot=str(op.get("robot", "")),
                what=f"downlink message {op.get('seq', '?')}",
                reason=str(op.get("message", "")),
            )
        )

    # -- one method per kind of event the report follows

    def _added(self, b: Batch, e: ev.SkillAdded) -> None:
        self.add(e.robot, e.skill)

    def _removed(self, b: Batch, e: ev.SkillRemoved) -> None:
        if e.id in self.rows and e.id not in self.synced:
            del self.rows[e.id]
            self.deleted += 1

    def _edited(self, b: Batch, e: ev.SkillEdited) -> None:
        if e.label is not None and e.id in self.rows:
            self.rows[e.id].label = e.label

    def _status(self, b: Batch, e: ev.SkillStatusChanged) -> None:
        row = self.rows.get(e.id)
        if row is None or e.status is None:
            return
        row.status = e.status
        if e.status != Status.IDLE:
            self.synced.add(row.id)
        if e.attempt is not None:
            row.attempt = e.attempt
        if e.at is not None:
            _robot_times(row, e.status, e.at)
        if e.status == Status.FAILURE:
            row.failures.append(e.info or "failed")

    def _replaced(self, b: Batch, e: ev.MissionReplaced) -> None:
        self.rows = {k: r for k, r in self.rows.items() if k in self.synced}
        self._add_tasks(e.mission)
        self.mission = e.mission.name

    def _waiver_set(self, b: Batch, e: ev.WaiverSet) -> None:
        waiver = WaiverRow(check=e.check, reason=e.waiver.reason, by=b.actor, at=_t(b.ts))
        self.waivers[e.check] = waiver
        self.waiver_log.append(waiver)

    def _waiver_removed(self, b: Batch, e: ev.WaiverRemoved) -> None:
        if e.check in self.waivers:
            self.waivers.pop(e.check).withdrawn = _t(b.ts)

    def _queued(self, b: Batch, e: ev.CommandQueued) -> None:
        self.commands[e.command.id] = (e.command.robot, e.command.title())

    def _command(self, b: Batch, e: ev.CommandChanged) -> None:
        if e.state == CommandState.REFUSED:
            robot, title = self.commands.get(e.id, ("", f"command {e.id}"))
            self.refusals.append(
                RefusalRow(at=_t(b.ts), robot=robot, what=title, reason=e.reason or "")
            )


# the operations the report reads (besides their events), by name
_ON_OP: dict[str, Callable[[_Pass, Batch], None]] = {
    "sync": _Pass._sync,
    "downlink_refused": _Pass._downlink_refused,
}
_ON_EVENT: dict[type[Any], Callable[[_Pass, Batch, Any], None]] = {
    ev.SkillAdded: _Pass._added,
    ev.SkillRemoved: _Pass._removed,
    ev.SkillEdited: _Pass._edited,
    ev.SkillStatusChanged: _Pass._status,
    ev.MissionReplaced: _Pass._replaced,
    ev.WaiverSet: _Pass._waiver_set,
    ev.WaiverRemoved: _Pass._waiver_removed,
    ev.CommandQueued: _Pass._queued,
    ev.CommandChanged: _Pass._command,
}


def _robot_times(row: SkillRow, status: Status, at: datetime) -> None:
    """When a skill started and ended by the robot's clock: its first run, its last end."""
    if status == Status.RUNNING and row.started is None:
        row.started = at
    if status in (Status.SUCCESS, Status.FAILURE):
        row.finished = at


def _ground_time(seconds: float | None) -> datetime | None:
    return _t(seconds) if seconds is not None else None


def _gap(reader: JournalReader) -> str:
    if not reader.gap:
        return ""
    return (
        f"the journal keeps what came after revision {reader.base} only (its older "
        "snapshots were not kept): earlier skills are not listed"
    )


def _actor_rows(actors: dict[str, Counter[str]]) -> list[ActorRow]:
    """Each actor's operations by kind, the busiest actor first."""
    return [
        ActorRow(actor=a, operations=dict(c.most_common()))
        for a, c in sorted(actors.items(), key=lambda kv: -sum(kv[1].values()))
    ]


def plan_against_actual(reader: JournalReader) -> PlanReport:
    """The report of the whole journal."""
    p = _Pass(reader.snapshot(reader.base))
    for b in reader.batches(reader.base + 1, reader.last):
        p.batch(b)
    synced = [r for r in p.rows.values() if r.id in p.synced]
    return PlanReport(
        journal=str(reader.path),
        mission=p.mission,
        start=_ground_time(reader.start_time()),
        end=_ground_time(reader.end_time()),
        changes=len(reader),
        gap=_gap(reader),
        skills=synced,
        deleted_unsynchronized=p.deleted,
        unsynchronized_at_end=len(p.rows) - len(synced),
        waivers=p.waiver_log,
        refusals=p.refusals,
        actors=_actor_rows(p.actors),
    )


# -- as text -------------------------------------------------------------------------------


def _clock(t: datetime | None) -> str:
    return t.astimezone().strftime("%H:%M:%S") if t is not None else "-"


def _delta(s: float | None) -> str:
    if s is None:
        return ""
    sign = "+" if s >= 0 else "-"
    s = abs(s)
    return f" ({sign}{s:.0f}s)" if s < 120 else f" ({sign}{s / 60:.1f}m)"


def _span(planned: datetime | None, actual: datetime | None, late: float | None) -> str:
    return f"{_clock(planned)}→{_clock(actual)}{_delta(late)}"


def _notes(k: SkillRow) -> str:
    """What a skill's line says after its spans: failures, retries, a missing forecast."""
    notes = [
        note
        for note, shown in (
            ("failed: " + "; ".join(k.failures), k.failures),
            (f"retry of {k.retry_of}", k.retry_of),
            (f"retried as {k.retried_as}", k.retried_as),
            ("no forecast sent with its sync", k.predicted_start is None and not k.retry_of),
        )
        if shown
    ]
    return f"  {'; '.join(notes)}" if notes else ""


def _skill_line(k: SkillRow) -> str:
    return (
        f"  {k.robot:<8} {k.id:<14} {k.skill:<18} {k.status.value:<17} "
        f"start {_span(k.predicted_start, k.started, k.start_late_s)}  "
        f"end {_span(k.predicted_end, k.finished, k.end_late_s)}" + _notes(k)
    )


def _heading(r: PlanReport) -> list[str]:
    out = [
        f"Plan against actual: {r.mission} ({r.journal}), {_clock(r.start)} to {_clock(r.end)} "
        f"ground wall time, {r.changes} changes",
        f"times: {WALL_NOTE}",
    ]
    if r.gap:
        out.append(f"note: {r.gap}")
    return out


def _skills(r: PlanReport) -> list[str]:
    out = [
        "Skills (start and end: as forecast when synchronized → as the robot did it, "
        "robot wall time; (+late / -early))",
        *map(_skill_line, r.skills),
    ]
    if not r.skills:
        out.append("  none was synchronized")
    out.append(
        f"  ({r.deleted_unsynchronized} deleted before being synchronized, "
        f"{r.unsynchronized_at_end} never synchronized)"
    )
    return out


def _failures(r: PlanReport) -> list[str]:
    failed = [k for k in r.skills if k.failures]
    out = [f"Failures and retries: {len(failed)} failed"]
    for k in failed:
        again = f", retried as {k.retried_as}" if k.retried_as else ", not retried"
        out.append(f"  {k.id} ({k.robot}) at {_clock(k.finished)}: {k.failures[-1]}{again}")
    return out


def _waivers(r: PlanReport) -> list[str]:
    out = [f"Waivers: {len(r.waivers)}"]
    for w in r.waivers:
        gone = f", withdrawn {_clock(w.withdrawn)}" if w.withdrawn else ""
        out.append(f"  {w.check}: {w.reason!r} by {w.by} at {_clock(w.at)}{gone}")
    return out


def _refusals(r: PlanReport) -> list[str]:
    return [f"Refusals: {len(r.refusals)}"] + [
        f"  {_clock(x.at)} {x.robot}: {x.what}: {x.reason}" for x in r.refusals
    ]


def _overdue(r: PlanReport) -> list[str]:
    return ["Overdue verifications: none listed", f"  ({r.overdue_note})"]


def _actors(r: PlanReport) -> list[str]:
    out = ["Who did what"]
    for a in r.actors:
        total = sum(a.operations.values())
        kinds = ", ".join(f"{op} {n}" for op, n in a.operations.items())
        out.append(f"  {a.actor}: {total} ({kinds})")
    return out


_SECTIONS = (_heading, _skills, _failures, _waivers, _refusals, _overdue, _actors)


def report_text(r: PlanReport) -> str:
    """The report for a person: a table per section, times in local wall time
    (said in its heading: BRIEF "One mission clock" names no clock wrongly)."""
    return "\n\n".join("\n".join(section(r)) for section in _SECTIONS) + "\n"
