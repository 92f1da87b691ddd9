"""Events: the small, ordered changes an applied operation makes.

`apply_events` is the only code that mutates a mission. The engine applies
the events it produces through it, the journal replays them through it, and
clients mirror the server through it — so the three cannot drift apart.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from datetime import datetime
from typing import Annotated, Any, Literal

from pydantic import Field, TypeAdapter, model_validator

from backend.core.model import (
    FINISHED,
    KEEP_SETTLED,
    Barrier,
    CheckId,
    Choice,
    CommandState,
    Marker,
    Mission,
    Name,
    Policies,
    Question,
    QuestionState,
    RobotSpec,
    SkillId,
    SkillInstance,
    Status,
    Strict,
    Taken,
    UplinkCommand,
    Waiver,
    json_copy,
)


class SkillAdded(Strict):
    ev: Literal["skill_added"] = "skill_added"
    robot: Name
    index: int
    skill: SkillInstance


class SkillRemoved(Strict):
    ev: Literal["skill_removed"] = "skill_removed"
    robot: Name
    id: SkillId


class SkillMoved(Strict):
    ev: Literal["skill_moved"] = "skill_moved"
    robot: Name
    id: SkillId
    index: int


class SkillStatusChanged(Strict):
    """A skill's execution moved on (a robot's report or answer, a reconcile).

    `at` is when it happened: the first `running` with it sets `started_at`,
    `success`/`failure` set `finished_at`; back to `idle` or
    `idle_synchronized` clears `started_at` (the next run starts afresh).
    `info` and `attempt` None leave them as they are; `status` None only in
    journals written before this event existed (an info-only change)."""

    ev: Literal["skill_status"] = "skill_status"
    id: SkillId
    status: Status | None = None
    info: str | None = None
    attempt: int | None = Field(None, ge=1)
    at: datetime | None = None
    # the contingency the robot took (kept until idle again); left out while unset
    branch: Taken | None = Field(None, exclude_if=lambda v: v is None)


class SkillEdited(Strict):
    """An operator's (or a marker's) change to a skill's plan: each field
    given replaces the skill's; None leaves it as it is."""

    ev: Literal["skill_edited"] = "skill_edited"
    id: SkillId
    label: str | None = None
    params: dict[str, Any] | None = None
    bindings: dict[str, Name] | None = None
    policies: Policies | None = None


class BarrierSet(Strict):
    ev: Literal["barrier_set"] = "barrier_set"
    id: Name
    barrier: Barrier


class BarrierRemoved(Strict):
    ev: Literal["barrier_removed"] = "barrier_removed"
    id: Name


class MarkerSet(Strict):
    ev: Literal["marker_set"] = "marker_set"
    name: Name
    marker: Marker


class MarkerRemoved(Strict):
    ev: Literal["marker_removed"] = "marker_removed"
    name: Name


class ReportSeq(Strict):
    """Highest report sequence number applied for a robot (idempotency)."""

    ev: Literal["report_seq"] = "report_seq"
    robot: Name
    seq: int


class CommandQueued(Strict):
    """A command joined its robot's uplink."""

    ev: Literal["command_queued"] = "command_queued"
    command: UplinkCommand


class CommandChanged(Strict):
    """A command moved on: each field given replaces the command's, None
    leaves it as it is (no field of a command is ever cleared)."""

    ev: Literal["command_changed"] = "command_changed"
    id: int
    state: CommandState | None = None
    sent: datetime | None = None
    settled: datetime | None = None
    answered: datetime | None = None
    cancel_requested: bool | None = None
    reason: str | None = None
    done: list[SkillId] | None = None
    kept: list[SkillId] | None = None

    @model_validator(mode="before")
    @classmethod
    def _flatten(cls, data: Any) -> Any:
        """Journals written before the fields were typed: {"changes": {...}}."""
        if isinstance(data, dict) and isinstance(data.get("changes"), dict):
            rest = {k: v for k, v in data.items() if k != "changes"}
            return {**rest, **data["changes"]}
        return data

    def changes(self) -> dict[str, Any]:
        """The fields it sets."""
        return self.model_dump(exclude={"ev", "id"}, exclude_none=True)


class WaiverSet(Strict):
    ev: Literal["waiver_set"] = "waiver_set"
    check: CheckId
    waiver: Waiver


class WaiverRemoved(Strict):
    ev: Literal["waiver_removed"] = "waiver_removed"
    check: CheckId


class RobotAdded(Strict):
    """A robot joined the mission (it registered with a type the library knows)."""

    ev: Literal["robot_added"] = "robot_added"
    name: Name
    spec: RobotSpec


class RobotRetired(Strict):
    """A robot was retired: no new syncs; its log stays."""

    ev: Literal["robot_retired"] = "robot_retired"
    name: Name
    reason: str = Field(min_length=1, max_length=500)


class QuestionAsked(Strict):
    """A robot's skill asked the operators a question (its `Ask`)."""

    ev: Literal["question_asked"] = "question_asked"
    question: Question


class QuestionAnswered(Strict):
    """An operator answered an open question: the answer is on its way up
    (`command`); the question stays open until the robot says it took it."""

    ev: Literal["question_answered"] = "question_answered"
    id: int
    choice: Choice
    by: str = ""
    at: datetime
    command: int


# how a question ends (QuestionState without `open`)
Closed = Literal[QuestionState.ANSWERED, QuestionState.DEFAULTED, QuestionState.WITHDRAWN]


class QuestionClosed(Strict):
    """How a robot's question ended, as the robot says (or the ground, for a
    robot that registered without it: withdrawn)."""

    ev: Literal["question_closed"] = "question_closed"
    id: int
    state: Closed
    choice: Choice | None = None
    at: datetime | None = None
    reason: str = ""


class MissionReplaced(Strict):
    ev: Literal["mission_replaced"] = "mission_replaced"
    mission: Mission


Event = Annotated[
    SkillAdded
    | SkillRemoved
    | SkillMoved
    | SkillStatusChanged
    | SkillEdited
    | BarrierSet
    | BarrierRemoved
    | MarkerSet
    | MarkerRemoved
    | ReportSeq
    | CommandQueued
    | CommandChanged
    | WaiverSet
    | WaiverRemoved
    | RobotAdded
    | RobotRetired
    | QuestionAsked
    | QuestionAnswered
    | QuestionClosed
    | MissionReplaced,
    Field(discriminator="ev"),
]


# what a journal written before the skill events were typed calls a skill's
# change, field by field: which typed event (and field) each one is now
_STATUS_FIELDS = {"status": "status", "status_info": "info", "attempt": "attempt"}
_EDIT_FIELDS = ("label", "params", "bindings", "policies")


def _is_old_skill_change(e: Any) -> bool:
    return isinstance(e, dict) and e.get("ev") == "skill_changed"


def _typed_skill_change(e: dict[str, Any]) -> list[dict[str, Any]]:
    """An old `skill_changed` event ({"id", "changes": {...}}) as the typed
    events that make the same change (a status and/or an edit)."""
    changes = e.get("changes")
    if not isinstance(changes, dict):
        return [e]  # not ours to mend: validation says what is wrong
    return _old_status(e.get("id"), changes) + _old_edit(e.get("id"), changes)


def _old_status(sid: Any, changes: dict[str, Any]) -> list[dict[str, Any]]:
    """The status part of an old skill change, as a `skill_status` event (if any)."""
    status = {new: changes[old] for old, new in _STATUS_FIELDS.items() if old in changes}
    stamp = changes.get("started_at") or changes.get("finished_at")
    if status or stamp is not None:
        return [{"ev": "skill_status", "id": sid, **status, "at": stamp}]
    return []


def _old_edit(sid: Any, changes: dict[str, Any]) -> list[dict[str, Any]]:
    """The edit part of an old skill change, as a `skill_edited` event (if any)."""
    edit = {k: changes[k] for k in _EDIT_FIELDS if k in changes}
    return [{"ev": "skill_edited", "id": sid, **edit}] if edit else []


class EventBatch(Strict):
    """What one applied operation changed; revisions are consecutive."""

    revision: int
    events: list[Event]

    @model_validator(mode="before")
    @classmethod
    def _old_skill_changes(cls, data: Any) -> Any:
        """Replay journals written before skill events were typed (`skill_changed`)."""
        if not isinstance(data, dict) or not isinstance(data.get("events"), list):
            return data
        events = data["events"]
        if not any(map(_is_old_skill_change, events)):
            return data
        typed: list[Any] = []
        for e in events:
            typed.extend(_typed_skill_change(e) if _is_old_skill_change(e) else [e])
        return {**data, "events": typed}

    actor: str = Field(
        "",
        description="who: 'user@client' when the request named a user, else the client id; "
        "the robot's name for its reports",
    )
    op: str = ""


_BATCHES = TypeAdapter(list[EventBatch])


def read_batches(payload: bytes) -> list[EventBatch]:
    """A message on the events key: one EventBatch, or a JSON array of
    consecutive ones (operations the server handled in a row)."""
    if payload.lstrip()[:1] == b"[":
        return _BATCHES.validate_json(payload)
    return [EventBatch.model_validate_json(payload)]


def _task_of(m: Mission, skill_id: str) -> tuple[list[SkillInstance], int]:
    found = m.find(skill_id)
    if found is None:
        raise KeyError(skill_id)
    robot, i, _ = found
    return m.tasks[robot], i


def _bump_counters(m: Mission, skill_id: str | None = None, barrier_id: str | None = None) -> None:
    if skill_id is not None:
        tail = skill_id.rsplit("-", 1)[-1]
        if tail.isdigit():
            m.next_skill = max(m.next_skill, int(tail) + 1)
    if barrier_id is not None and barrier_id[1:].isdigit():
        m.next_barrier = max(m.next_barrier, int(barrier_id[1:]) + 1)


def _queue_command(m: Mission, e: CommandQueued, revision: int) -> None:
    c = e.command
    m.uplink.setdefault(c.robot, []).append(json_copy(c))
    m.next_command = max(m.next_command, c.id + 1)
    m.uplink_seqs[c.robot] = max(m.uplink_seqs.get(c.robot, 0), c.seq)


def _change_command(m: Mission, change: CommandChanged, revision: int) -> None:
    command_id = change.id
    for cmds in m.uplink.values():
        for i, c in enumerate(cmds):
            if c.id == command_id:
                cmds[i] = c.model_copy(update=change.changes())
                if not cmds[i].pending:
                    _prune(cmds)
                return
    raise KeyError(f"command {command_id}")


def _prune(cmds: list[UplinkCommand]) -> None:
    """Keep the pending commands and the last KEEP_SETTLED settled ones."""
    settled = [i for i, c in enumerate(cmds) if not c.pending]
    for i in reversed(settled[:-KEEP_SETTLED] if len(settled) > KEEP_SETTLED else []):
        del cmds[i]


def _stamps(s: SkillInstance, status: Status, at: datetime | None) -> dict[str, Any]:
    """The start or the finish that `status`, reported at `at`, stamps on `s`."""
    if at is None:
        return {}
    if status == Status.RUNNING and s.started_at is None:
        return {"started_at": at}
    if status in FINISHED:
        return {"finished_at": at}
    return {}


def _skill_status(m: Mission, e: SkillStatusChanged, revision: int) -> None:
    task, i = _task_of(m, e.id)
    s = task[i]
    status = e.status if e.status is not None else s.status
    update: dict[str, Any] = {"rev": revision, "status": status, **_stamps(s, status, e.at)}
    if e.info is not None:
        update["status_info"] = e.info
    if e.attempt is not None:
        update["attempt"] = e.attempt
    if e.status in (Status.IDLE, Status.IDLE_SYNCHRONIZED):
        update["started_at"] = None
        update["branch"] = None
    if e.branch is not None:
        update["branch"] = e.branch
    task[i] = s.model_copy(update=update)


def _skill_edited(m: Mission, e: SkillEdited, revision: int) -> None:
    task, i = _task_of(m, e.id)
    edit = {k: getattr(e, k) for k in _EDIT_FIELDS if getattr(e, k) is not None}
    # the mission's own copies: an event may be kept (journal, history)
    task[i] = task[i].model_copy(update={**copy.deepcopy(edit), "rev": revision})


def _waiver_set(m: Mission, e: WaiverSet, revision: int) -> None:
    m.waivers[e.check] = e.waiver.model_copy(update={"revision": revision})


def _waiver_removed(m: Mission, e: WaiverRemoved, revision: int) -> None:
    m.waivers.pop(e.check, None)


def _robot_added(m: Mission, e: RobotAdded, revision: int) -> None:
    m.robots[e.name] = e.spec.model_copy()
    m.tasks.setdefault(e.name, [])
    m.task_revs[e.name] = revision


def _robot_retired(m: Mission, e: RobotRetired, revision: int) -> None:
    m.robots[e.name] = m.robots[e.name].model_copy(update={"retired": e.reason})
    m.task_revs[e.name] = revision


def _question_asked(m: Mission, e: QuestionAsked, revision: int) -> None:
    q = e.question.model_copy()
    m.questions.setdefault(q.robot, []).append(q)
    m.next_question = max(m.next_question, q.id + 1)


def _question_changed(m: Mission, qid: int, update: dict[str, Any]) -> None:
    for qs in m.questions.values():
        for i, q in enumerate(qs):
            if q.id == qid:
                qs[i] = q.model_copy(update=update)
                if not qs[i].is_open:
                    _prune_questions(qs)
                return
    raise KeyError(f"question {qid}")


def _prune_questions(qs: list[Question]) -> None:
    """Keep the open questions and the last KEEP_SETTLED closed ones."""
    closed = [i for i, q in enumerate(qs) if not q.is_open]
    for i in reversed(closed[:-KEEP_SETTLED] if len(closed) > KEEP_SETTLED else []):
        del qs[i]


def _question_answered(m: Mission, e: QuestionAnswered, revision: int) -> None:
    update = {"answer": e.choice, "answered_by": e.by, "answered_at": e.at, "command": e.command}
    _question_changed(m, e.id, update)


def _question_closed(m: Mission, e: QuestionClosed, revision: int) -> None:
    update = {"state": e.state, "choice": e.choice, "closed": e.at, "reason": e.reason}
    _question_changed(m, e.id, update)


def _skill_added(m: Mission, e: SkillAdded, revision: int) -> None:
    s = json_copy(e.skill)
    s.rev = revision
    m.tasks.setdefault(e.robot, []).insert(e.index, s)
    m.hint(e.robot, e.index, s.id)
    m.task_revs[e.robot] = revision
    _bump_counters(m, skill_id=s.id)


def _skill_removed(m: Mission, e: SkillRemoved, revision: int) -> None:
    task, i = _task_of(m, e.id)
    del task[i]
    m.task_revs[e.robot] = revision


def _skill_moved(m: Mission, e: SkillMoved, revision: int) -> None:
    task, i = _task_of(m, e.id)
    task.insert(e.index, task.pop(i))
    m.task_revs[e.robot] = revision


def _barrier_set(m: Mission, e: BarrierSet, revision: int) -> None:
    m.barriers[e.id] = e.barrier.model_copy(deep=True)
    _bump_counters(m, barrier_id=e.id)


def _barrier_removed(m: Mission, e: BarrierRemoved, revision: int) -> None:
    m.barriers.pop(e.id, None)


def _marker_set(m: Mission, e: MarkerSet, revision: int) -> None:
    m.markers[e.name] = e.marker.model_copy(deep=True)
    m.marker_revs[e.name] = revision


def _marker_removed(m: Mission, e: MarkerRemoved, revision: int) -> None:
    m.markers.pop(e.name, None)
    m.marker_revs.pop(e.name, None)


def _report_seq(m: Mission, e: ReportSeq, revision: int) -> None:
    m.report_seqs[e.robot] = e.seq


# what each event changes in a mission, by its type (MissionReplaced
# replaces the mission instead: apply_event's own case)
_APPLY: dict[type[Any], Callable[[Mission, Any, int], None]] = {
    SkillAdded: _skill_added,
    SkillRemoved: _skill_removed,
    SkillMoved: _skill_moved,
    SkillStatusChanged: _skill_status,
    SkillEdited: _skill_edited,
    BarrierSet: _barrier_set,
    BarrierRemoved: _barrier_removed,
    MarkerSet: _marker_set,
    MarkerRemoved: _marker_removed,
    ReportSeq: _report_seq,
    CommandQueued: _queue_command,
    CommandChanged: _change_command,
    WaiverSet: _waiver_set,
    WaiverRemoved: _waiver_removed,
    RobotAdded: _robot_added,
    RobotRetired: _robot_retired,
    QuestionAsked: _question_asked,
    QuestionAnswered: _question_answered,
    QuestionClosed: _question_closed,
}


def apply_event(m: Mission, ev: Any, revision: int) -> Mission:
    """Apply one event in place (or return the replacement mission)."""
    if isinstance(ev, MissionReplaced):
        return ev.mission.copy_deep()
    apply = _APPLY.get(type(ev))
    if apply is None:
        raise TypeError(f"unknown event {ev!r}")
    apply(m, ev, revision)
    return m


def apply_events(m: Mission, batch: EventBatch) -> Mission:
    for ev in batch.events:
        m = apply_event(m, ev, batch.revision)
    m.revision = batch.revision
    return m
