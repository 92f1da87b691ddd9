"""Execution: the robots' reports, and the direct path of commands.

The server sends commands through the uplink (`backend.core.rules.uplink`).
The direct path here is for tools and tests that play the robot themselves:
a command is two-phase, one at a time per robot:
1. plan it: `plan_sync`, `plan_unsync`, `plan_control`, `plan_retry` check it
   and say what to send, without changing the mission. Planning claims the
   robot (`pending`) and, for a sync, locks the skills it sends;
2. the robot's answer is an operation submitted like any other: `SyncAck`,
   `UnsyncDone`, `RetryAck` (rules `sync_ack`, `unsync_done`, `retry_ack`);
3. `release` ends the command, whether the robot answered, refused or never
   answered; until then the robot takes no other command.
A robot's `Report`s (status changes, numbered per robot) come without a command.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from datetime import datetime
from typing import Any

from backend.core import events as ev
from backend.core.model import ACTIVE, FINISHED, TRANSITIONS, Mission, SkillInstance, Status
from backend.core.ops import (
    Control,
    Report,
    Retry,
    RetryAck,
    Sync,
    SyncAck,
    Unsync,
    UnsyncDone,
)
from backend.core.plan.gate import check_sync
from backend.core.rules import choose
from backend.core.rules.base import Change, Refusal, Rule, Rules, skill_of

# -- commands: claim, plan, release ---------------------------------------------


def claim(rules: Rules, robot: str) -> None:
    """Refused while another command to `robot` is in flight."""
    if robot in rules.pending:
        raise Refusal(
            "robot_busy",
            f"{robot} is busy: {rules.pending[robot]} is in progress; try again when it ends",
            robot=robot,
        )


def release(rules: Rules, robot: str, ids: Iterable[str] = ()) -> None:
    """The command to `robot` ended (answered, refused or timed out)."""
    rules.pending.pop(robot, None)
    for sid in ids:
        rules.held.pop(sid, None)
        rules.sent.pop(sid, None)


def of_robot(rules: Rules, robot: str, skill_id: str) -> tuple[int, SkillInstance]:
    """Index and skill `skill_id`, refused unless it is in `robot`'s list."""
    return skill_of(rules.mission, robot, skill_id)


# which skills a sync sends (the one rule: backend.core.rules.uplink.sync_skills)
Choose = Callable[[Mission, Sync, Mapping[str, str]], list[SkillInstance]]


def plan_sync(rules: Rules, op: Sync, choose: Choose) -> list[SkillInstance]:
    """Skills to send to the robot (`choose` says which); they are locked
    until `release` or the robot's `SyncAck`."""
    rules.task(op.robot)
    claim(rules, op.robot)
    chosen = choose(rules.mission, op, rules.locked)
    check_sync(rules, op.robot, [s.id for s in chosen])  # unwaived plan errors stay on the ground
    # check against the current library and markers; bound values are
    # taken fresh from their markers as they leave
    fresh = [
        rules.check_params(op.robot, s.skill, s.params, s.bindings, skill_id=s.id) for s in chosen
    ]
    for s, params in zip(chosen, fresh, strict=True):
        rules.held[s.id] = f"it is being synchronized to {op.robot}"
        rules.sent[s.id] = params
    rules.pending[op.robot] = "a sync"
    return [
        s.model_copy(update={"params": p}, deep=True) for s, p in zip(chosen, fresh, strict=True)
    ]


def plan_unsync(rules: Rules, op: Unsync) -> list[str]:
    """Queued skills to take back, from `op.from_id` (or all) to the end."""
    task = rules.task(op.robot)
    claim(rules, op.robot)
    queued = [s for s in task if s.status == Status.IDLE_SYNCHRONIZED]
    if not queued:
        raise Refusal(
            "nothing_to_unsync",
            f"{op.robot} has no queued (idle_synchronized) skill to unsynchronize",
            robot=op.robot,
        )
    if op.from_id is not None:
        _, s = of_robot(rules, op.robot, op.from_id)
        queued = queued_from(op.robot, s, queued)
    rules.pending[op.robot] = "an unsync"
    return [s.id for s in queued]


def queued_from(robot: str, s: SkillInstance, queued: list[SkillInstance]) -> list[SkillInstance]:
    """The robot's queued skills from `s` on (an unsync's `from`): `s` must be queued."""
    if s.status != Status.IDLE_SYNCHRONIZED:
        raise Refusal(
            "not_queued",
            f"{s.display()} on {robot} is {s.status.value}; only queued "
            "(idle_synchronized) skills can be unsynchronized",
            robot=robot,
            skill=s.id,
        )
    return queued[[q.id for q in queued].index(s.id) :]


def plan_control(rules: Rules, op: Control) -> list[str]:
    """Robots the command goes to; refused when it applies to none."""
    robots = [op.robot] if op.robot is not None else list(rules.mission.robots)
    out, reasons = _takers(rules, op.op, robots)
    if not out:
        raise _applies_to_none(op, reasons)
    if op.op == "reset":
        _claim_resets(rules, out)
    return out


def _takers(rules: Rules, command: str, robots: list[str]) -> tuple[list[str], list[str]]:
    """The robots that can take the command, and why each other cannot."""
    out: list[str] = []
    reasons: list[str] = []
    for r in robots:
        why = _control_refusal(rules, command, r, rules.task(r))
        if why is None:
            out.append(r)
        else:
            reasons.append(why)
    return out, reasons


def _claim_resets(rules: Rules, robots: list[str]) -> None:
    """The robots answer a reset: one command at a time (refused if one
    has a command pending)."""
    for r in robots:
        claim(rules, r)
    for r in robots:
        rules.pending[r] = "a reset"


def _applies_to_none(op: Control, reasons: list[str]) -> Refusal:
    """The refusal of a command no robot can take: the robot's reason, or
    every robot's."""
    if op.robot is not None:
        return Refusal("not_applicable", reasons[0], robot=op.robot)
    return Refusal("not_applicable", f"{op.op} applies to no robot: " + "; ".join(reasons))


def _why_not_run(robot: str, act: SkillInstance | None, queued: bool) -> str | None:
    if act is not None and act.status == Status.PAUSED:
        return None
    if act is not None:
        return f"{robot} is already executing {act.display()} ({act.status.value})"
    return None if queued else f"{robot} has nothing to run: synchronize skills first"


def _why_not_pause(robot: str, act: SkillInstance | None, queued: bool) -> str | None:
    if act is not None and act.status == Status.RUNNING:
        return None
    return f"{robot} has no running skill to pause"


def _why_not_stop(robot: str, act: SkillInstance | None, queued: bool) -> str | None:
    if act is not None:
        return None
    return f"{robot} has no running, paused or waiting skill to stop"


def _why_not_reset(robot: str, act: SkillInstance | None, queued: bool) -> str | None:
    if act is not None or queued:
        return None
    return f"{robot} has nothing synchronized to reset"


# control command -> why it does not apply to a robot (given its active skill
# and whether it has queued skills), or None when it does
_WHY_NOT: dict[str, Callable[[str, SkillInstance | None, bool], str | None]] = {
    "run": _why_not_run,
    "pause": _why_not_pause,
    "stop": _why_not_stop,
    "reset": _why_not_reset,
}


def why_not(action: str, robot: str, act: SkillInstance | None, queued: bool) -> str | None:
    """Why `action` does not apply to `robot` (its active skill, whether it
    has queued skills), or None when it does."""
    rule = _WHY_NOT.get(action)
    if rule is None:
        return f"unknown command {action}"
    return rule(robot, act, queued)


def _control_refusal(
    rules: Rules, action: str, robot: str, task: list[SkillInstance]
) -> str | None:
    return why_not(action, robot, rules.active(task), rules.first_queued(task) is not None)


def plan_retry(rules: Rules, op: Retry) -> SkillInstance:
    """The new attempt of a failed skill, to send to its robot."""
    robot, i, s = rules.skill(op.id)
    check_retriable(rules, robot, i, s)
    claim(rules, robot)
    rules.pending[robot] = "a retry"
    return s.next_attempt(Status.IDLE_SYNCHRONIZED)


def check_failed_once(rules: Rules, robot: str, s: SkillInstance) -> None:
    """`s` failed and has no next attempt yet (a retry, or an edit and retry)."""
    if s.status != Status.FAILURE:
        raise Refusal(
            "cannot_retry",
            f"{s.display()} on {robot} is {s.status.value}; only a failed skill can be retried",
            robot=robot,
            skill=s.id,
        )
    if rules.mission.find(s.retry_id()) is not None:
        raise Refusal(
            "cannot_retry",
            f"{s.display()} was already retried as {s.retry_id()}",
            robot=robot,
            skill=s.id,
        )


def check_retriable(rules: Rules, robot: str, i: int, s: SkillInstance) -> None:
    """A retry sent to the robot: `s` failed, was not retried, and nothing ran after it."""
    check_failed_once(rules, robot, s)
    task = rules.task(robot)
    if any(later.status in FINISHED for later in task[i + 1 :]):
        raise Refusal(
            "cannot_retry",
            f"{robot} has executed other skills since {s.display()} failed; "
            "add a new skill instead",
            robot=robot,
            skill=s.id,
        )
    act = rules.active(task)
    if act is not None:
        raise Refusal(
            "cannot_retry",
            f"cannot retry {s.display()}: {robot} is executing {act.display()}; stop it first",
            robot=robot,
            skill=s.id,
        )


# -- the robots' answers to commands ---------------------------------------------


def sync_ack(rules: Rules, op: SyncAck) -> Change:
    task = rules.task(op.robot)
    start = rules.first_idle(task)
    acked = task[start : start + len(op.ids)]
    _check_acked(rules, op, [s.id for s in acked])
    events: list[ev.Event] = []
    for s in acked:
        events.append(ev.SkillStatusChanged(id=s.id, status=Status.IDLE_SYNCHRONIZED))
        if rules.sent[s.id] != s.params:  # what the robot holds
            events.append(ev.SkillEdited(id=s.id, params=rules.sent[s.id]))
    for sid in op.ids:
        rules.held.pop(sid, None)
        rules.sent.pop(sid, None)
    return Change(events, [], {"synchronized": list(op.ids)}, None)


def _check_acked(rules: Rules, op: SyncAck, head: list[str]) -> None:
    """Refused unless the robot acknowledges the head of its unsynchronized
    section, all of it being synchronized."""
    if head != list(op.ids):
        raise Refusal(
            "bad_report",
            f"{op.robot} acknowledged {op.ids}, but the head of its unsynchronized section "
            f"is {head}",
            robot=op.robot,
        )
    late = [sid for sid in op.ids if sid not in rules.sent]
    if late:
        # the sync was given up (and the skill maybe edited since): the
        # robot's copy is not ours; reconciliation sorts it out
        raise Refusal(
            "bad_report",
            f"{op.robot} acknowledged {', '.join(late)}, which is not being synchronized",
            robot=op.robot,
        )


def unsync_done(rules: Rules, op: UnsyncDone) -> Change:
    task = rules.task(op.robot)
    queued = [s.id for s in task if s.status == Status.IDLE_SYNCHRONIZED]
    if op.ids and list(op.ids) != queued[-len(op.ids) :]:
        raise Refusal(
            "bad_report",
            f"{op.robot} removed {op.ids}, which is not the end of its queue {queued}",
            robot=op.robot,
        )
    # the removed skills are the end of the queue: turning them idle puts
    # them, in order, at the head of the unsynchronized section
    events = [e for sid in op.ids for e in back_in_plan(rules, op.robot, sid)]
    return Change(events, [], {"unsynchronized": list(op.ids)}, None)


def back_in_plan(rules: Rules, robot: str, sid: str) -> list[ev.Event]:
    """The events of a skill the robot gave back: idle again."""
    _, _, s = rules.skill(sid)
    events: list[ev.Event] = [ev.SkillStatusChanged(id=sid, status=Status.IDLE, info="")]
    if s.bindings:  # back in the plan: bound values follow their markers again
        try:
            params = rules.check_params(robot, s.skill, s.params, s.bindings, skill_id=sid)
            if params != s.params:
                events.append(ev.SkillEdited(id=sid, params=params))
        except Refusal:
            pass  # keeps its values; the operator sees the problem on the next edit
    return events


def retry_ack(rules: Rules, op: RetryAck) -> Change:
    robot, i, failed = rules.skill(op.failed_id)
    if robot != op.robot or failed.status != Status.FAILURE:
        raise Refusal(
            "bad_report",
            f"{op.robot} acknowledged a retry of {op.failed_id}, which is not a failed skill of it",
            robot=op.robot,
        )
    if rules.mission.find(op.skill.id) is not None:
        raise Refusal("bad_report", f"skill {op.skill.id} exists already", robot=op.robot)
    skill = op.skill.model_copy(update={"status": Status.IDLE_SYNCHRONIZED})
    events: list[ev.Event] = [ev.SkillAdded(robot=robot, index=i + 1, skill=skill)]
    return Change(events, [], {"id": skill.id}, None)


# -- what robots tell without a command -------------------------------------------


def report(rules: Rules, op: Report) -> Change:
    """A robot's status change for one of its skills, applied once (by number)."""
    last = rules.mission.report_seqs.get(op.robot, 0)
    if op.seq <= last:
        ignored = f"report {op.seq} of {op.robot} was applied already"
        return Change([], [], {"ignored": ignored}, None, duplicate=True)
    robot, i, s = _reported_skill(rules, op)
    _check_transition(robot, s, op)
    _check_turn(rules, robot, i, s, op.status)
    _check_attempt(robot, s, op)
    events: list[ev.Event] = [ev.ReportSeq(robot=robot, seq=op.seq)]
    change = _reported_change(s, op)
    if change is not None:
        events.append(change)
    placed, alerts = choose.reported(rules, op)  # markers it chose on board
    return Change(events + placed, [], {}, None, alerts=tuple(alerts))


def _reported_skill(rules: Rules, op: Report) -> tuple[str, int, SkillInstance]:
    """(robot, index, skill) a report is about; refused if the mission has no
    such skill or it is another robot's."""
    rules.task(op.robot)
    found = rules.mission.find(op.id)
    if found is None:  # a robot's message: refused like every report the rules refuse
        raise Refusal(
            "bad_report",
            f"{op.robot} reported on skill {op.id}, which this mission does not have",
            robot=op.robot,
            skill=op.id,
        )
    robot, _, s = found
    if robot != op.robot:
        raise Refusal(
            "bad_report",
            f"{op.robot} reported on {s.display()}, which belongs to {robot}",
            robot=op.robot,
            skill=s.id,
        )
    return found


def _check_attempt(robot: str, s: SkillInstance, op: Report) -> None:
    """Refused if the report is about an earlier attempt than the skill's."""
    if op.attempt is not None and op.attempt < s.attempt:
        raise Refusal(
            "bad_report",
            f"{robot} reported attempt {op.attempt} of {s.display()}, which is at attempt "
            f"{s.attempt}",
            robot=robot,
            skill=s.id,
        )


def _check_transition(robot: str, s: SkillInstance, op: Report) -> None:
    """Refused unless the transition table allows the new status."""
    new = op.status
    if new in TRANSITIONS[s.status] or _may_repeat(s, op):
        return
    again = (
        f" at the same attempt {s.attempt} (only a retry, with a higher attempt, reports "
        "running again)"
        if new == s.status == Status.RUNNING
        else ""
    )
    raise Refusal(
        "bad_report",
        f"{robot} reported {s.display()} going {s.status.value} -> {new.value}{again}, "
        "which the transition table forbids",
        robot=robot,
        skill=s.id,
    )


def _may_repeat(s: SkillInstance, op: Report) -> bool:
    """A skill reporting its status again: waiting at a barrier, with new
    information ("waiting for lru2 (offline)"); running, with a higher
    attempt (a retry) or to say which contingency it took (a fallback, a
    goto, over time); the others never."""
    if op.status != s.status:
        return False
    if s.status == Status.SYNCHWAITING:
        return True
    return s.status == Status.RUNNING and ((op.attempt or 0) > s.attempt or op.branch is not None)


def _check_turn(rules: Rules, robot: str, i: int, s: SkillInstance, new: Status) -> None:
    """A skill executes (or ends) only when no other one is active and the
    skills queued ahead of it are done."""
    if new not in ACTIVE and new not in FINISHED:
        return
    task = rules.mission.tasks[robot]
    act = rules.active(task)
    if act is not None and act.id != s.id:
        raise Refusal(
            "bad_report",
            f"{robot} reported {s.display()} {new.value} while {act.display()} is "
            f"{act.status.value}",
            robot=robot,
            skill=s.id,
        )
    if s.status == Status.IDLE_SYNCHRONIZED and rules.first_queued(task) != i:
        raise Refusal(
            "bad_report",
            f"{robot} started {s.display()} before the skills queued ahead of it",
            robot=robot,
            skill=s.id,
        )


def _reported_change(s: SkillInstance, op: Report) -> ev.SkillStatusChanged | None:
    """What a report changes of the skill (None: nothing)."""
    new = op.status
    info = op.info if op.info != s.status_info else None
    attempt = op.attempt if op.attempt is not None and op.attempt != s.attempt else None
    branch = op.branch if op.branch != s.branch else None
    change = ev.SkillStatusChanged(
        id=s.id, status=new, info=info, attempt=attempt, at=_stamp(s, op), branch=branch
    )
    return None if change == ev.SkillStatusChanged(id=s.id, status=s.status) else change


def _stamp(s: SkillInstance, op: Report) -> datetime | None:
    """The report's time, kept when it starts the skill or ends it."""
    starts = op.status == Status.RUNNING and s.started_at is None
    return op.at if starts or op.status in FINISHED else None


RULES: dict[type[Any], Rule] = {
    SyncAck: sync_ack,
    UnsyncDone: unsync_done,
    RetryAck: retry_ack,
    Report: report,
}
