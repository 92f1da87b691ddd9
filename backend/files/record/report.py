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
from datetime import UTC, datetime

from pydantic import BaseModel, Field

from backend.core import events as ev
from backend.core.model import CommandState, SkillInstance, Status
from backend.files.record.journal import Batch, JournalReader

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
    """What the pass keeps while it reads the batches."""

    def __init__(self) -> None:
        self.rows: dict[str, SkillRow] = {}
        self.synced: set[str] = set()
        self.deleted = 0
        self.waivers: dict[str, WaiverRow] = {}
        self.waiver_log: list[WaiverRow] = []
        self.refusals: list[RefusalRow] = []
        self.commands: dict[int, tuple[str, str]] = {}  # id -> (robot, title)
        self.actors: dict[str, Counter[str]] = {}

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

    def batch(self, b: Batch) -> None:
        self.actors.setdefault(b.actor or b.client or "?", Counter())[b.name] += 1
        if b.name == "sync":
            self._sync(b)
        elif b.name == "downlink_refused":
            op = b.op
            self.refusals.append(
                RefusalRow(
                    at=_t(b.ts),
                    robot=str(op.get("robot", "")),
                    what=f"downlink message {op.get('seq', '?')}",
                    reason=str(op.get("message", "")),
                )
            )
        for e in b.batch.events:
            self.event(b, e)

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

    def event(self, b: Batch, e: ev.Event) -> None:  # noqa: C901 - one case per event kind
        match e:
            case ev.SkillAdded(robot=robot, skill=s):
                self.add(robot, s)
            case ev.SkillRemoved(id=sid):
                row = self.rows.get(sid)
                if row is not None and sid not in self.synced:
                    del self.rows[sid]
                    self.deleted += 1
            case ev.SkillEdited(id=sid, label=label) if label is not None and sid in self.rows:
                self.rows[sid].label = label
            case ev.SkillStatusChanged(id=sid) if sid in self.rows:
                self._status(self.rows[sid], e)
            case ev.MissionReplaced(mission=m):
                self.rows = {k: r for k, r in self.rows.items() if k in self.synced}
                for robot, task in m.tasks.items():
                    for s in task:
                        self.add(robot, s)
            case ev.WaiverSet(check=check, waiver=w):
                waiver = WaiverRow(check=check, reason=w.reason, by=b.actor, at=_t(b.ts))
                self.waivers[check] = waiver
                self.waiver_log.append(waiver)
            case ev.WaiverRemoved(check=check) if check in self.waivers:
                self.waivers.pop(check).withdrawn = _t(b.ts)
            case ev.CommandQueued(command=c):
                self.commands[c.id] = (c.robot, c.title())
            case ev.CommandChanged(id=cid, state=CommandState.REFUSED):
                robot, title = self.commands.get(cid, ("", f"command {cid}"))
                self.refusals.append(
                    RefusalRow(at=_t(b.ts), robot=robot, what=title, reason=e.reason or "")
                )
            case _:
                pass

    def _status(self, row: SkillRow, e: ev.SkillStatusChanged) -> None:
        if e.status is None:
            return
        row.status = e.status
        if e.status != Status.IDLE:
            self.synced.add(row.id)
        if e.attempt is not None:
            row.attempt = e.attempt
        if e.status == Status.RUNNING and row.started is None and e.at is not None:
            row.started = e.at
        if e.status in (Status.SUCCESS, Status.FAILURE) and e.at is not None:
            row.finished = e.at
        if e.status == Status.FAILURE:
            row.failures.append(e.info or "failed")


def plan_against_actual(reader: JournalReader) -> PlanReport:
    """The report of the whole journal."""
    p = _Pass()
    base = reader.snapshot(reader.base)
    for robot, task in base.tasks.items():
        for s in task:
            p.add(robot, s)
    mission = base.name
    for b in reader.batches(reader.base + 1, reader.last):
        p.batch(b)
        for e in b.batch.events:
            if isinstance(e, ev.MissionReplaced):
                mission = e.mission.name
    start, end = reader.start_time(), reader.end_time()
    gap = (
        f"the journal keeps what came after revision {reader.base} only (its older "
        "snapshots were not kept): earlier skills are not listed"
        if reader.gap
        else ""
    )
    return PlanReport(
        journal=str(reader.path),
        mission=mission,
        start=_t(start) if start is not None else None,
        end=_t(end) if end is not None else None,
        changes=len(reader),
        gap=gap,
        skills=[r for r in p.rows.values() if r.id in p.synced],
        deleted_unsynchronized=p.deleted,
        unsynchronized_at_end=sum(1 for r in p.rows.values() if r.id not in p.synced),
        waivers=p.waiver_log,
        refusals=p.refusals,
        actors=[
            ActorRow(actor=a, operations=dict(c.most_common()))
            for a, c in sorted(p.actors.items(), key=lambda kv: -sum(kv[1].values()))
        ],
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
        f"ground time, {r.changes} changes",
    ]
    if r.gap:
        out.append(f"note: {r.gap}")
    return out


def _skills(r: PlanReport) -> list[str]:
    out = [
        "Skills (start and end: as forecast when synchronized → as the robot did it, "
        "robot time; (+late / -early))",
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
    """The report for a person: a table per section, times in local time."""
    return "\n\n".join("\n".join(section(r)) for section in _SECTIONS) + "\n"
