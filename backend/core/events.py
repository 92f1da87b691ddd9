"""Events: the small, ordered changes an applied operation makes.

`apply_events` is the only code that mutates a mission. The engine applies
the events it produces through it, the journal replays them through it, and
clients mirror the server through it — so the three cannot drift apart.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, TypeAdapter

from backend.core.model import (
    KEEP_SETTLED,
    Barrier,
    CheckId,
    Marker,
    Mission,
    Name,
    SkillId,
    SkillInstance,
    Strict,
    UplinkCommand,
    Waiver,
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


class SkillChanged(Strict):
    """Changed fields of one skill (JSON values), e.g. {"status": "running"}."""

    ev: Literal["skill_changed"] = "skill_changed"
    id: SkillId
    changes: dict[str, Any]


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
    """Changed fields of one command (JSON values), e.g. {"state": "sent", "sent": "..."}."""

    ev: Literal["command_changed"] = "command_changed"
    id: int
    changes: dict[str, Any]


class WaiverSet(Strict):
    ev: Literal["waiver_set"] = "waiver_set"
    check: CheckId
    waiver: Waiver


class WaiverRemoved(Strict):
    ev: Literal["waiver_removed"] = "waiver_removed"
    check: CheckId


class MissionReplaced(Strict):
    ev: Literal["mission_replaced"] = "mission_replaced"
    mission: Mission


Event = Annotated[
    SkillAdded
    | SkillRemoved
    | SkillMoved
    | SkillChanged
    | BarrierSet
    | BarrierRemoved
    | MarkerSet
    | MarkerRemoved
    | ReportSeq
    | CommandQueued
    | CommandChanged
    | WaiverSet
    | WaiverRemoved
    | MissionReplaced,
    Field(discriminator="ev"),
]


class EventBatch(Strict):
    """What one applied operation changed; revisions are consecutive."""

    revision: int
    events: list[Event]
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


def _queue_command(m: Mission, c: UplinkCommand) -> None:
    m.uplink.setdefault(c.robot, []).append(c.model_copy(deep=True))
    m.next_command = max(m.next_command, c.id + 1)
    m.uplink_seqs[c.robot] = max(m.uplink_seqs.get(c.robot, 0), c.seq)


def _change_command(m: Mission, command_id: int, changes: dict[str, Any]) -> None:
    for cmds in m.uplink.values():
        for i, c in enumerate(cmds):
            if c.id == command_id:
                data = c.model_dump()
                data.update(changes)
                cmds[i] = UplinkCommand.model_validate(data)
                if not cmds[i].pending:
                    _prune(cmds)
                return
    raise KeyError(f"command {command_id}")


def _prune(cmds: list[UplinkCommand]) -> None:
    """Keep the pending commands and the last KEEP_SETTLED settled ones."""
    settled = [i for i, c in enumerate(cmds) if not c.pending]
    for i in reversed(settled[:-KEEP_SETTLED] if len(settled) > KEEP_SETTLED else []):
        del cmds[i]


def apply_event(m: Mission, ev: Any, revision: int) -> Mission:
    """Apply one event in place (or return the replacement mission)."""
    match ev:
        case SkillAdded(robot=robot, index=index, skill=skill):
            s = skill.model_copy(deep=True)
            s.rev = revision
            m.tasks.setdefault(robot, []).insert(index, s)
            m.task_revs[robot] = revision
            _bump_counters(m, skill_id=s.id)
        case SkillRemoved(robot=robot, id=sid):
            task, i = _task_of(m, sid)
            del task[i]
            m.task_revs[robot] = revision
        case SkillMoved(robot=robot, id=sid, index=index):
            task, i = _task_of(m, sid)
            task.insert(index, task.pop(i))
            m.task_revs[robot] = revision
        case SkillChanged(id=sid, changes=changes):
            task, i = _task_of(m, sid)
            data = task[i].model_dump()
            data.update(changes)
            data["rev"] = revision
            task[i] = SkillInstance.model_validate(data)
        case BarrierSet(id=bid, barrier=b):
            m.barriers[bid] = b.model_copy(deep=True)
            _bump_counters(m, barrier_id=bid)
        case BarrierRemoved(id=bid):
            m.barriers.pop(bid, None)
        case MarkerSet(name=name, marker=marker):
            m.markers[name] = marker.model_copy(deep=True)
            m.marker_revs[name] = revision
        case MarkerRemoved(name=name):
            m.markers.pop(name, None)
            m.marker_revs.pop(name, None)
        case ReportSeq(robot=robot, seq=seq):
            m.report_seqs[robot] = seq
        case CommandQueued(command=c):
            _queue_command(m, c)
        case CommandChanged(id=cid, changes=changes):
            _change_command(m, cid, changes)
        case WaiverSet(check=check, waiver=w):
            m.waivers[check] = w.model_copy(update={"revision": revision})
        case WaiverRemoved(check=check):
            m.waivers.pop(check, None)
        case MissionReplaced(mission=new):
            m = new.copy_deep()
        case _:
            raise TypeError(f"unknown event {ev!r}")
    return m


def apply_events(m: Mission, batch: EventBatch) -> Mission:
    for ev in batch.events:
        m = apply_event(m, ev, batch.revision)
    m.revision = batch.revision
    return m
