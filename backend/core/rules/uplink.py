"""The uplink: commands to robots as entries of the mission, and the robots'
answers.

An operation on a robot (sync, unsync, run, pause, stop, reset, retry) does
not wait for the robot: it adds a command to the robot's uplink
(`CommandQueued`) and returns. Its skills are locked while it is pending
(`base.uplink_locks`). The server transmits pending commands in order
(`UplinkSent` once they may be on the robot) and gives up on the ones that
expire before they could leave, or whose cancel was asked while they were on
their way and never arrived (`UplinkSettle`). The robot answers each command
once (`Answer`, numbered with its reports); what it says it did is what the
mission shows: the ids it really queued or removed, never the request.

`Reconcile` makes the mission agree with a robot's own queue when it
registers (both ways). Every sentence an operator must see (a refusal by the
robot, a command given up, a robot that applied a command the ground had
given up on) is returned as the change's alerts (`Change.alerts`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from collections.abc import Set as AbstractSet
from datetime import datetime, timedelta
from typing import Any

from backend.core import events as ev
from backend.core.alerts import AlertKind, Level, RaisedAlert
from backend.core.model import (
    ACTIVE,
    FINISHED,
    BarrierInfo,
    CommandOp,
    CommandState,
    Dequeue,
    Enqueue,
    Mission,
    ParamType,
    Pause,
    Reset,
    RobotCommand,
    Run,
    SkillInstance,
    Status,
    Stop,
    UplinkCommand,
)
from backend.core.ops import (
    Answer,
    Cancel,
    Control,
    DownlinkRefused,
    QueueEntry,
    Reconcile,
    Retry,
    Sync,
    Unsync,
    UplinkSent,
    UplinkSettle,
)
from backend.core.plan.gate import check_sync
from backend.core.rules import barriers, choose, contingency, questions
from backend.core.rules.base import (
    Change,
    Refusal,
    Rule,
    Rules,
    check_in_service,
    robot_type,
    skill_of,
    unchanged,
)
from backend.core.rules.execution import (
    back_in_plan,
    check_retriable,
    of_robot,
    queued_from,
    why_not,
)

# -- new commands -------------------------------------------------------------


class _Maker:
    """Numbers the commands one operation adds (ids and seqs go on from the mission's)."""

    def __init__(self, rules: Rules, expire_s: float | None):
        self.rules = rules
        self.now = rules.clock()
        self.expires = self.now + timedelta(seconds=expire_s) if expire_s else None
        self.next_id = rules.mission.next_command
        self.seqs: dict[str, int] = {}

    def make(
        self, robot: str, op: CommandOp, command: RobotCommand, skills: Iterable[str] = ()
    ) -> UplinkCommand:
        seq = self.seqs.get(robot, self.rules.mission.uplink_seqs.get(robot, 0)) + 1
        self.seqs[robot] = seq
        c = UplinkCommand(
            id=self.next_id,
            robot=robot,
            seq=seq,
            op=op,
            command=command,
            skills=list(skills),
            created=self.now,
            expires=self.expires,
        )
        self.next_id += 1
        return c


def _expiry(rules: Rules, op: Sync | Unsync | Control | Retry) -> float | None:
    """Seconds the operator gave the command, else the server's default."""
    return op.expire_s if op.expire_s is not None else rules.default_expiry_s


def check_offered(rules: Rules, robot: str, skills: Sequence[SkillInstance]) -> None:
    """Refused (`incompatible`) when `robot` does not offer one of `skills`, or
    offers it with another major version than the library's. A robot that
    never registered is not judged: it refuses what it cannot run itself."""
    offered = rules.offers.offered(robot) if rules.offers is not None else None
    if offered is None:
        return
    for s in skills:
        spec = rules.library.skills.get(s.skill)
        why = incompatible(offered, s.skill, spec.version) if spec is not None else None
        if why:
            raise Refusal(
                "incompatible",
                f"{robot} {why}; {s.id} stays unsynchronized (nothing was queued)",
                robot=robot,
                skill=s.id,
            )


def incompatible(offered: Mapping[str, str], skill: str, want: str) -> str | None:
    """Why a robot offering `offered` cannot run `skill` at version `want`."""
    have = offered.get(skill)
    if have is None:
        return (
            f"does not offer skill '{skill}' (its manifest lists: {', '.join(offered) or 'none'})"
        )
    if have.split(".", 1)[0] != want.split(".", 1)[0]:
        return f"implements {skill} {have}, the library needs {want} (major versions differ)"
    return None


def _kinds(rules: Rules, skills: Sequence[SkillInstance]) -> dict[str, dict[str, ParamType]]:
    """The kind of each parameter of the skills sent: they travel with the values."""
    lib = rules.library.skills
    return {s.skill: lib[s.skill].kinds() for s in skills if s.skill in lib}


def _queued_value(c: UplinkCommand) -> dict[str, Any]:
    return {
        "command": c.id,
        "robot": c.robot,
        "seq": c.seq,
        "state": c.state.value,
        "skills": list(c.skills),
        "expires": c.expires.isoformat() if c.expires else None,
    }


def sync(rules: Rules, op: Sync) -> Change:
    """The idle head of the robot's unsynchronized section (through
    `op.through`) goes to the robot; its skills are uplinking until it answers."""
    rules.task(op.robot)
    check_in_service(rules, op.robot)
    chosen = sync_skills(rules.mission, op, rules.locked)
    check_offered(rules, op.robot, chosen)
    check_sync(rules, op.robot, [s.id for s in chosen])  # unwaived plan errors stay on the ground
    fresh = [
        rules.check_params(op.robot, s.skill, s.params, s.bindings, skill_id=s.id) for s in chosen
    ]
    skills = [
        s.model_copy(update={"params": p}, deep=True) for s, p in zip(chosen, fresh, strict=True)
    ]
    found = contingency.branches(rules, op.robot, skills)
    check_offered(rules, op.robot, contingency.run_by(found))
    c = _Maker(rules, _expiry(rules, op)).make(
        op.robot,
        "sync",
        Enqueue(
            skills=skills,
            barriers=_barrier_infos(rules, skills),
            kinds={**contingency.kinds(rules, found), **_kinds(rules, skills)},
            contingencies=found,
            after=contingency.afters(rules, skills),
            choose=choose.on_board(rules, op.robot, skills),
        ),
        [s.id for s in skills],
    )
    return Change(
        [ev.CommandQueued(command=c)],
        [],
        _queued_value(c),
        Cancel(command=c.id, undo=True),
    )


def _barrier_infos(rules: Rules, skills: Sequence[SkillInstance]) -> dict[str, BarrierInfo]:
    """What the robot must know of each sent skill's barrier: its partners
    (robot, skill), its timeout and what to do then."""
    infos: dict[str, BarrierInfo] = {}
    for s in skills:
        partners = barriers.barrier_partners(rules, s.id)
        bid = rules.mission.barrier_of(s.id)
        if partners and bid is not None:
            b = rules.mission.barriers[bid]
            infos[s.id] = BarrierInfo(
                barrier=bid, partners=dict(partners), timeout=b.timeout, on_timeout=b.on_timeout
            )
    return infos


def sync_skills(m: Mission, op: Sync, locked: Mapping[str, str]) -> list[SkillInstance]:
    """Which skills a sync sends: the idle skills of `op.robot` after those
    being synchronized already (`locked`: they stay at the head of its plan),
    through `op.through`; refused when there is none.

    The one rule: the sync, the direct path (`Engine.plan_sync`), the
    server's check against the robot's manifest and the console's
    availability of its sync action ask it."""
    robot_type(m, op.robot)
    task = m.tasks.get(op.robot, [])
    start = _after_uplinking(task, locked)
    if op.through is None:
        idle = task[start:]
    else:
        idle = task[start : _through(m, op.robot, op.through, locked) + 1]
    if not idle:
        busy = [s.id for s in task if s.status == Status.IDLE and s.id in locked]
        more = f" ({', '.join(busy)} are being synchronized already)" if busy else ""
        raise Refusal(
            "nothing_to_sync",
            f"{op.robot} has no unsynchronized skill to synchronize{more}",
            robot=op.robot,
        )
    return idle


def _after_uplinking(task: list[SkillInstance], locked: Mapping[str, str]) -> int:
    """Where a new sync starts: the first idle skill after those being
    synchronized already (they stay at the head of the section)."""
    start = Rules.first_idle(task)
    while start < len(task) and task[start].id in locked:
        start += 1
    return start


def _through(m: Mission, robot: str, through: str, locked: Mapping[str, str]) -> int:
    """The index of the last skill a sync sends, refused unless it is idle
    and not locked."""
    i, s = skill_of(m, robot, through)
    if s.status != Status.IDLE:
        raise Refusal(
            "not_idle",
            f"{s.display()} on {robot} is already {s.status.value}: synchronize "
            "through an idle (unsynchronized) skill",
            robot=robot,
            skill=s.id,
        )
    _check_unlocked(robot, s, locked)
    return i


def _check_unlocked(robot: str, s: SkillInstance, locked: Mapping[str, str]) -> None:
    """Refused while a pending command concerns `s`."""
    if s.id in locked:
        raise Refusal("locked", f"{s.display()}: {locked[s.id]}", robot=robot, skill=s.id)


def unsync(rules: Rules, op: Unsync) -> Change:
    """Ask the robot to give back its queued skills from `op.from_id` (or all)."""
    task = rules.task(op.robot)
    locked = rules.locked
    queued = [s for s in task if s.status == Status.IDLE_SYNCHRONIZED and s.id not in locked]
    if op.from_id is not None:
        _, s = of_robot(rules, op.robot, op.from_id)
        _check_unlocked(op.robot, s, locked)
        queued = queued_from(op.robot, s, queued)
    if not queued:
        raise Refusal(
            "nothing_to_unsync",
            f"{op.robot} has no queued (idle_synchronized) skill to unsynchronize",
            robot=op.robot,
        )
    ids = [s.id for s in queued]
    c = _Maker(rules, _expiry(rules, op)).make(op.robot, "unsync", Dequeue(ids=ids), ids)
    return Change([ev.CommandQueued(command=c)], [], _queued_value(c), None)


_CONTROL: dict[str, Callable[[], RobotCommand]] = {
    "run": Run,
    "pause": Pause,
    "stop": Stop,
    "reset": Reset,
}


def control(rules: Rules, op: Control) -> Change:
    """run / pause / stop / reset, for one robot or all it applies to."""
    robots = [op.robot] if op.robot is not None else list(rules.mission.robots)
    maker = _Maker(rules, _expiry(rules, op))
    events: list[ev.Event] = []
    results: dict[str, str] = {}
    commands: dict[str, int] = {}
    for r in robots:
        why = _why_not_now(rules, op.op, r)
        if why is not None:
            results[r] = why
            continue
        c = maker.make(r, op.op, _CONTROL[op.op]())
        events.append(ev.CommandQueued(command=c))
        results[r] = "queued"
        commands[r] = c.id
    if not events:
        if op.robot is not None:
            raise Refusal("not_applicable", results[op.robot], robot=op.robot)
        raise Refusal(
            "not_applicable", f"{op.op} applies to no robot: " + "; ".join(results.values())
        )
    value = {"robots": results, "commands": commands}
    return Change(events, _not_sent(rules, op, results), value, None)


def _not_sent(rules: Rules, op: Control, results: dict[str, str]) -> list[str]:
    """Where the command did not go, and why; not a retired robot's when it was
    for all (it gets no new syncs: "nothing to run, synchronize" would mislead)."""
    quiet = _retired(rules, op)
    said = [(r, why) for r, why in results.items() if why != "queued"]
    return [f"{op.op} not sent: {why}" for r, why in said if r not in quiet]


def _retired(rules: Rules, op: Control) -> set[str]:
    """The retired robots a command for all went past (none for one robot)."""
    if op.robot is not None:
        return set()
    return {r for r, spec in rules.mission.robots.items() if spec.retired}


def _why_not_now(rules: Rules, action: str, robot: str) -> str | None:
    """Why `action` does not apply to `robot`, judged on what the ground knows
    plus its pending commands (the robot may have started a queued skill by
    now: pause and stop apply while a run is pending)."""
    task = rules.task(robot)
    pending = {c.op for c in rules.mission.pending_commands(robot)}
    act = rules.active(task)
    queued = rules.first_queued(task) is not None
    if pending_allows(action, act, queued, pending):
        return None
    return why_not(action, robot, act, queued)


def pending_allows(
    action: str, act: SkillInstance | None, queued: bool, pending: AbstractSet[str]
) -> bool:
    """Whether `action` applies because of the robot's pending commands (ops),
    though what the ground knows says not: run or reset what a pending sync
    brings, pause or stop what a pending run may have started."""
    if act is not None:
        return False
    if action in ("run", "reset"):
        return not queued and bool(pending & {"sync", "retry"})
    if action in ("pause", "stop"):
        return queued and "run" in pending
    return False


def retry(rules: Rules, op: Retry) -> Change:
    """A new attempt of a failed skill, sent to the front of its robot's queue;
    it joins the mission (right after the failed one) once the robot has it."""
    robot, i, s = rules.skill(op.id)
    check_offered(rules, robot, [s])
    why = rules.locked.get(s.id)
    if why is not None:
        raise Refusal("cannot_retry", f"{s.display()}: {why}", robot=robot, skill=s.id)
    check_retriable(rules, robot, i, s)
    new = s.next_attempt(Status.IDLE_SYNCHRONIZED)
    # its markers resolved again, as a sync does: one chosen on board (or
    # moved) since the failed attempt went up sends its place, not the old one
    new.params = rules.check_params(robot, new.skill, new.params, new.bindings, skill_id=new.id)
    found = contingency.branches(rules, robot, [new])
    check_offered(rules, robot, contingency.run_by(found))
    c = _Maker(rules, _expiry(rules, op)).make(
        robot,
        "retry",
        Enqueue(
            skills=[new],
            front=True,
            kinds={**contingency.kinds(rules, found), **_kinds(rules, [new])},
            contingencies=found,
            after=contingency.afters(rules, [new]),
            choose=choose.on_board(rules, robot, [new]),
        ),
        [s.id, new.id],
    )
    return Change([ev.CommandQueued(command=c)], [], {**_queued_value(c), "id": new.id}, None)


# -- withdrawing ----------------------------------------------------------------


def cancel(rules: Rules, op: Cancel) -> Change:
    c = rules.mission.command(op.command)
    if c is None:
        raise Refusal("unknown_command", f"no command {op.command} in this mission")
    if not c.pending:
        raise _settled_already(c, op.undo)
    now = rules.clock()
    if c.state == CommandState.QUEUED and c.id not in rules.transmitting:
        change = ev.CommandChanged(
            id=c.id, state=CommandState.CANCELLED, settled=now, reason="cancelled"
        )
        value = {"command": c.id, "robot": c.robot, "state": "cancelled"}
        return Change([change], [], value, None)
    return _cancel_asked(c, op.undo)


def _settled_already(c: UplinkCommand, undo: bool) -> Refusal:
    """The refusal of a cancel (or a sync's undo) of a command settled already."""
    said = f": {c.reason}" if c.reason else ""
    if undo:  # the sync reached the robot (or never will): nothing to take back here
        return Refusal(
            "cannot_undo",
            f"{c.title()} to {c.robot} is {c.state.value} already{said}; "
            "unsynchronize what it queued instead",
            robot=c.robot,
        )
    return Refusal(
        "not_pending",
        f"{c.title()} to {c.robot} is {c.state.value} already{said}",
        robot=c.robot,
    )


def _cancel_asked(c: UplinkCommand, undo: bool) -> Change:
    """A command that may be on the robot already: its cancel is a request
    the robot's answer settles (an undo is refused)."""
    if undo:
        raise Refusal(
            "cannot_undo",
            f"{c.title()} may be on {c.robot} already (it was sent); "
            f"`missionctl ctl cancel {c.id}` asks {c.robot} not to apply it",
            robot=c.robot,
        )
    value = {"command": c.id, "robot": c.robot, "state": c.state.value, "cancel_requested": True}
    note = (
        f"{c.robot} may have {c.title()} already: it is cancelled unless {c.robot} applied "
        "it first; its answer says which"
    )
    if c.cancel_requested:
        return Change([], [note], value, None)
    events: list[ev.Event] = [ev.CommandChanged(id=c.id, cancel_requested=True)]
    return Change(events, [note], value, None)


def uplink_sent(rules: Rules, op: UplinkSent) -> Change:
    events: list[ev.Event] = []
    for cid in op.ids:
        c = rules.mission.command(cid)
        if c is not None and c.state == CommandState.QUEUED:
            events.append(ev.CommandChanged(id=cid, state=CommandState.SENT, sent=op.at))
    return Change(events, [], {}, None) if events else unchanged()


def uplink_settle(rules: Rules, op: UplinkSettle) -> Change:
    """Commands that never left for the robot and never will."""
    events: list[ev.Event] = []
    alerts: list[RaisedAlert] = []
    for cid in op.ids:
        c = rules.mission.command(cid)
        if c is None or c.state != CommandState.QUEUED or cid in rules.transmitting:
            continue
        events.append(ev.CommandChanged(id=cid, state=op.state, settled=op.at, reason=op.reason))
        if op.state == CommandState.EXPIRED:
            alerts.append(_alert(c, f"{c.title()} to {c.robot} {op.reason}{_released(c)}"))
    return Change(events, [], {}, None, alerts=tuple(alerts)) if events else unchanged()


def _released(c: UplinkCommand) -> str:
    if c.op == "sync":
        return f"; {', '.join(c.skills)} are unsynchronized (idle) again"
    if c.op == "unsync":
        return f"; {', '.join(c.skills)} stay on {c.robot}"
    if c.op == "answer":
        return f"; {c.robot} goes on with the question's default"
    return ""


def _alert(c: UplinkCommand, message: str, level: Level = "warning") -> RaisedAlert:
    return RaisedAlert(
        message=message, robot=c.robot, command=c.id, level=level, kind=AlertKind.COMMAND
    )


# -- the robot's answers ----------------------------------------------------------


_STATE = {
    "applied": CommandState.ACKED,
    "refused": CommandState.REFUSED,
    "expired": CommandState.EXPIRED,
    "cancelled": CommandState.CANCELLED,
}


class _Effects:
    """What applying a command's answer changes: events, alerts, notes, and
    the statuses and placements the robot's truth asks for."""

    def __init__(self, rules: Rules, c: UplinkCommand, op: Answer):
        self.rules, self.c, self.op = rules, c, op
        self.robot = c.robot
        self.task = rules.task(c.robot)
        self.events: list[ev.Event] = []
        self.alerts: list[RaisedAlert] = []
        self.notes: list[str] = []
        self.done: list[str] = []
        self.late = c.state in (CommandState.CANCELLED, CommandState.EXPIRED)
        self.drop: list[str] = []  # skills the robot holds that it must not: asked back

    def alert(self, message: str, level: Level = "warning") -> None:
        self.alerts.append(_alert(self.c, message, level))

    def skill(self, sid: str) -> SkillInstance | None:
        found = self.rules.mission.find(sid)
        return found[2] if found is not None and found[0] == self.robot else None


def answer(rules: Rules, op: Answer) -> Change:
    """A robot's answer: applied once, in its downlink order."""
    last = rules.mission.report_seqs.get(op.robot, 0)
    if op.seq <= last:
        return Change([], [], {"ignored": f"answer {op.seq} was applied already"}, None, True)
    rules.task(op.robot)
    events: list[ev.Event] = [ev.ReportSeq(robot=op.robot, seq=op.seq)]
    c = _answered_command(rules, op)
    fx = _Effects(rules, c, op)
    _take_outcome(fx)
    state = _STATE[op.outcome]
    events += fx.events
    events.append(_command_ended(fx, state, op.at or rules.clock()))
    if fx.drop:
        events.append(_drop_command(rules, fx.robot, fx.drop, fx))
    value = {"command": c.id, "state": state.value}
    return Change(events, fx.notes, value, None, alerts=tuple(fx.alerts))


def _answered_command(rules: Rules, op: Answer) -> UplinkCommand:
    """The command an answer is about, refused unless it waits for one."""
    c = rules.mission.command_by_seq(op.robot, op.command)
    if c is not None and c.answered is None:
        return c
    what = (
        "which its uplink does not hold (never sent, or settled long ago)"
        if c is None
        else f"{c.title()}, answered already"
    )
    raise Refusal(
        "bad_report",
        f"{op.robot} answered command seq {op.command}, {what}: nothing of it was applied",
        robot=op.robot,
    )


def _take_outcome(fx: _Effects) -> None:
    """What the robot says it did with the command, applied; what it did
    not do, said (unless the ground had given up on the command)."""
    c, op = fx.c, fx.op
    if op.outcome == "applied":
        _APPLIED[c.command.cmd](fx)
        if fx.late:
            fx.alert(
                f"{op.robot} applied {c.title()} after the ground had given up on it "
                f"({c.state.value}: {c.reason or 'no reason'}); the mission shows what it did"
            )
    elif not fx.late:
        fx.alert(
            f"{op.robot} {op.outcome} {c.title()}: {op.reason or 'no reason given'}{_released(c)}"
        )


def _command_ended(fx: _Effects, state: CommandState, at: datetime) -> ev.Event:
    """The answered command as it ends: its state, when, and what the robot
    did of it."""
    c, op = fx.c, fx.op
    return ev.CommandChanged(
        id=c.id,
        state=state,
        settled=at,
        answered=at,
        reason=op.reason,
        sent=at if c.sent is None else None,
        done=fx.done or None,
        kept=[k for k in op.kept if k in c.skills] if op.kept else None,
    )


def _drop_command(rules: Rules, robot: str, ids: list[str], fx: _Effects) -> ev.Event:
    c = _Maker(rules, None).make(robot, "reconcile", Dequeue(ids=ids), ids)
    fx.alert(
        f"{robot} holds {', '.join(ids)}, which the mission does not give it as queued: "
        f"asked it to drop them (command {c.id})"
    )
    return ev.CommandQueued(command=c)


def _enqueued(fx: _Effects) -> None:
    cmd = fx.c.command
    assert isinstance(cmd, Enqueue)
    if cmd.front:
        _retried(fx, cmd)
        return
    sent = {s.id: s for s in cmd.skills}
    held = _held(fx, sent)
    _say_not_queued(fx, [sid for sid in sent if sid not in fx.op.queued])
    status: dict[str, Status] = {}
    for sid in held:
        fx.events += _now_queued(fx, sent[sid])
        status[sid] = Status.IDLE_SYNCHRONIZED
    fx.events += _arrangement(fx.robot, fx.task, status, queued_last=held)
    fx.done = held


def _held(fx: _Effects, sent: dict[str, SkillInstance]) -> list[str]:
    """The ids the robot says it queued that the mission shows as queued now;
    the others it holds are to drop, an id never sent is said and ignored."""
    held: list[str] = []
    for sid in fx.op.queued:
        s = fx.skill(sid)
        if sid not in sent:
            fx.alert(
                f"{fx.robot} says it queued {sid}, which {fx.c.title()} did not send: ignored",
                "error",
            )
        elif s is None or s.status != Status.IDLE or (fx.late and _edited(s, sent[sid])):
            fx.drop.append(sid)  # not ours to show as queued any more
        else:
            held.append(sid)
    return held


def _say_not_queued(fx: _Effects, missing: list[str]) -> None:
    """The skills sent that the robot did not queue (idle again), and why,
    unless the ground had given up on the command."""
    if missing and not fx.late:
        why = f": {fx.op.reason}" if fx.op.reason else ""
        fx.alert(
            f"{fx.robot} did not queue {', '.join(missing)} ({fx.c.title()}){why}; "
            "they are unsynchronized (idle) again"
        )


def _now_queued(fx: _Effects, sent: SkillInstance) -> list[ev.Event]:
    """A skill the robot holds, synchronized, with the values it was sent."""
    s = fx.skill(sent.id)
    assert s is not None
    out: list[ev.Event] = [ev.SkillStatusChanged(id=sent.id, status=Status.IDLE_SYNCHRONIZED)]
    if sent.params != s.params:  # what the robot holds
        out.append(ev.SkillEdited(id=sent.id, params=sent.params))
    return out


def _edited(s: SkillInstance, sent: SkillInstance) -> bool:
    """Changed since it was sent (the command had been given up on)."""
    return (s.skill, s.label, s.params, s.policies) != (
        sent.skill,
        sent.label,
        sent.params,
        sent.policies,
    )


def _retried(fx: _Effects, cmd: Enqueue) -> None:
    new = cmd.skills[0]
    failed_id = fx.c.skills[0] if fx.c.skills else ""
    if new.id not in fx.op.queued:
        if not fx.late:
            fx.alert(
                f"{fx.robot} did not queue the retry {new.id} of {failed_id}: "
                f"{fx.op.reason or 'no reason given'}"
            )
        return
    if not _retry_fits(fx, new.id, failed_id):
        fx.drop.append(new.id)
        return
    index = _queue_head(fx.task)
    skill = new.model_copy(update={"status": Status.IDLE_SYNCHRONIZED})
    fx.events.append(ev.SkillAdded(robot=fx.robot, index=index, skill=skill))
    fx.done = [new.id]


def _retry_fits(fx: _Effects, new_id: str, failed_id: str) -> bool:
    """Whether a retry the robot queued can join the mission: its id is
    free and the skill it retries is still this robot's."""
    found = fx.rules.mission.find(failed_id)
    return fx.rules.mission.find(new_id) is None and found is not None and found[0] == fx.robot


def _queue_head(task: list[SkillInstance]) -> int:
    """Where the head of the robot's queue is: after the log and the active skill."""
    return next(
        (k for k, s in enumerate(task) if s.status not in FINISHED and s.status not in ACTIVE),
        len(task),
    )


def _dequeued(fx: _Effects) -> None:
    asked = set(fx.c.skills) if fx.c.op != "reset" else None
    _returned_to_plan(fx, [sid for sid in fx.op.removed if _removal_taken(fx, sid, asked)])
    kept = [k for k in fx.op.kept if k in fx.c.skills]
    if kept:
        fx.notes.append(f"{fx.robot} had already started {', '.join(kept)}: it stays synchronized")


def _returned_to_plan(fx: _Effects, removed: list[str]) -> None:
    """The skills the robot removed, idle again at the head of the plan in
    the mission's order."""
    status: dict[str, Status] = {}
    ordered = [s.id for s in fx.task if s.id in removed]
    for sid in ordered:
        fx.events += back_in_plan(fx.rules, fx.robot, sid)  # (idle: started_at cleared)
        status[sid] = Status.IDLE
    fx.events += _arrangement(fx.robot, fx.task, status, idle_first=ordered)
    fx.done = ordered


def _removal_taken(fx: _Effects, sid: str, asked: AbstractSet[str] | None) -> bool:
    """Whether the mission takes the robot's word that it removed `sid`:
    one it was asked to remove (`asked`; None: any, a reset) that it held.
    A removal it was not asked for, or of a finished skill, is said."""
    if asked is not None and sid not in asked:
        if fx.c.op != "reconcile":
            fx.alert(
                f"{fx.robot} says it removed {sid}, which {fx.c.title()} did not ask for: ignored",
                "error",
            )
        return False
    s = fx.skill(sid)
    if s is None or s.status == Status.IDLE:
        return False  # nothing the mission shows as on the robot
    if s.status in FINISHED:
        fx.alert(
            f"{fx.robot} says it removed {sid}, which it had finished "
            f"({s.status.value}): the log stays",
            "error",
        )
        return False
    return True


def _controlled(fx: _Effects) -> None:
    if fx.c.op == "reset":
        _dequeued(fx)
    elif fx.op.reason:
        fx.notes.append(f"{fx.robot}: {fx.op.reason}")


_APPLIED: dict[str, Callable[[_Effects], None]] = {
    "enqueue": _enqueued,
    "dequeue": _dequeued,
    "run": _controlled,
    "pause": _controlled,
    "stop": _controlled,
    "reset": _controlled,
    "answer": questions.applied_answer,
}


# -- placing skills where their (new) statuses belong ---------------------------


def _arrangement(
    robot: str,
    task: list[SkillInstance],
    status: dict[str, Status],
    *,
    queued_last: Sequence[str] = (),
    idle_first: Sequence[str] = (),
    held_order: Sequence[str] = (),
) -> list[ev.Event]:
    """SkillMoved events putting `task` (with the statuses in `status`
    overriding) in section order: the log, the active skill and the queue
    (`held_order`: the robot's own order; `queued_last` at the end), then the
    plan (`idle_first` at its head). Relative order is kept otherwise."""
    last = {sid: k for k, sid in enumerate(queued_last)}
    first = {sid: k for k, sid in enumerate(idle_first)}
    held = {sid: k for k, sid in enumerate(held_order)}

    def key(item: tuple[int, SkillInstance]) -> tuple[int, int, int]:
        pos, s = item
        st = status.get(s.id, s.status)
        if st in FINISHED:
            return (0, 0, pos)
        if st == Status.IDLE:
            return (3, 0, first[s.id]) if s.id in first else (3, 1, pos)
        rank = 1 if st in ACTIVE else 2
        if s.id in held:
            return (rank, 0, held[s.id])
        return (rank, 1, last[s.id]) if s.id in last else (rank, 0, pos)

    target = [s.id for _, s in sorted(enumerate(task), key=key)]
    current = [s.id for s in task]
    events: list[ev.Event] = []
    for index, sid in enumerate(target):
        if current[index] != sid:
            current.insert(index, current.pop(current.index(sid)))
            events.append(ev.SkillMoved(robot=robot, id=sid, index=index))
    return events


# -- a robot's registration: agree with its own queue ---------------------------


def reconcile(rules: Rules, op: Reconcile) -> Change:
    robot = op.robot
    task = rules.task(robot)
    mine = {s.id: s for s in task}
    queue, alerts = _checked_queue(robot, op.queue)
    held, adopted, strays = _sorted_queue(rules, robot, mine, queue)
    lost = _lost(task, queue)
    events, status = _reconciled_statuses(robot, mine, lost, held)
    events += _arrangement(robot, task, status, idle_first=lost, held_order=[e.id for e in held])
    events += questions.reconciled(rules, op)
    said = _reconcile_sentences(robot, lost, adopted)
    if strays:
        c = _Maker(rules, None).make(robot, "reconcile", Dequeue(ids=strays), strays)
        events.append(ev.CommandQueued(command=c))
        said.append(
            f"{robot} holds {', '.join(strays)}, which this mission does not give it (or not "
            f"as it has them): asked it to drop them (command {c.id})"
        )
    alerts += [_robot_alert(robot, text, AlertKind.RECONCILE) for text in said]
    value: dict[str, Any] = {"unsynchronized": lost, "adopted": adopted, "dropped": strays}
    return Change(events, [], value, None, alerts=tuple(alerts))


def _lost(task: list[SkillInstance], queue: list[QueueEntry]) -> list[str]:
    """The skills the mission has on the robot's side (synchronized or
    under way) that its registered queue no longer holds."""
    holds = {e.id for e in queue}
    return [
        s.id
        for s in task
        if s.status != Status.IDLE and s.status not in FINISHED and s.id not in holds
    ]


def _reconciled_statuses(
    robot: str, mine: dict[str, SkillInstance], lost: list[str], held: list[QueueEntry]
) -> tuple[list[ev.Event], dict[str, Status]]:
    """The status events of a registration (the skills `robot` lost back
    in the plan, those it holds as it has them) and each one's new status."""
    info = f"returned to the plan: {robot} no longer had it"
    events: list[ev.Event] = [
        ev.SkillStatusChanged(id=sid, status=Status.IDLE, info=info) for sid in lost
    ]
    status = dict.fromkeys(lost, Status.IDLE)
    for e in held:
        if e.status != mine[e.id].status:
            events.append(ev.SkillStatusChanged(id=e.id, status=e.status))
        status[e.id] = e.status
    return events, status


def _reconcile_sentences(robot: str, lost: list[str], adopted: list[str]) -> list[str]:
    """What a registration says of the skills `robot` lost and those it adopted."""
    said = []
    if lost:
        said.append(f"{robot} no longer had {', '.join(lost)}: returned to the plan")
    if adopted:
        said.append(
            f"{robot} holds {', '.join(adopted)}, which the mission had as unsynchronized: "
            "shown as synchronized again (unsync to take them back)"
        )
    return said


def _sorted_queue(
    rules: Rules, robot: str, mine: dict[str, SkillInstance], queue: list[QueueEntry]
) -> tuple[list[QueueEntry], list[str], list[str]]:
    """The robot's queue as the mission sees it: (entries it holds as the
    mission has them, the ids of those the mission had as idle: adopted, the
    ids of those it must drop: strays). One being synchronized is left to
    the answer of its sync."""
    uplinking = _uplinking(rules, robot)
    held: list[QueueEntry] = []
    adopted: list[str] = []
    strays: list[str] = []
    for e in queue:
        s = mine.get(e.id)
        if s is None or s.status in FINISHED or _differs(e, s):
            strays.append(e.id)
        elif e.id not in uplinking:
            if s.status == Status.IDLE:
                adopted.append(e.id)
            held.append(e)
    return held, adopted, strays


def _uplinking(rules: Rules, robot: str) -> set[str]:
    """The skills a pending sync or retry is bringing to `robot`."""
    return {
        sid
        for c in rules.mission.pending_commands(robot)
        if c.op in ("sync", "retry")
        for sid in c.skills
    }


def _robot_alert(
    robot: str, message: str, kind: AlertKind, level: Level = "warning"
) -> RaisedAlert:
    return RaisedAlert(message=message, robot=robot, level=level, kind=kind)


def _checked_queue(
    robot: str, queue: list[QueueEntry]
) -> tuple[list[QueueEntry], list[RaisedAlert]]:
    """The robot's queue, active first; one that breaks that is read as all queued."""
    first: dict[str, QueueEntry] = {}
    for e in queue:
        first.setdefault(e.id, e)  # an id said twice: its first entry
    out = list(first.values())
    if _active_then_queued(out):
        return out, []
    fixed = [e.model_copy(update={"status": Status.IDLE_SYNCHRONIZED}) for e in out]
    msg = (
        f"{robot} registered a queue that is not an active skill followed by queued ones "
        f"({', '.join(f'{e.id} {e.status.value}' for e in out)}): read as all queued"
    )
    return fixed, [_robot_alert(robot, msg, AlertKind.ROBOT_ERROR, "error")]


def _active_then_queued(queue: list[QueueEntry]) -> bool:
    """A queue as a robot holds one: at most one active skill, first, then
    queued ones (none finished, none idle)."""
    active = [k for k, e in enumerate(queue) if e.status in ACTIVE]
    wrong = [e for e in queue if e.status in FINISHED or e.status == Status.IDLE]
    return active in ([], [0]) and not wrong


def _differs(e: QueueEntry, s: SkillInstance) -> bool:
    """The robot's copy is another skill than the mission's (when it says)."""
    if e.skill is not None and e.skill != s.skill:
        return True
    return s.status == Status.IDLE and e.params is not None and e.params != s.params


def downlink_refused(rules: Rules, op: DownlinkRefused) -> Change:
    """A refused message of a robot's downlink still uses up its number."""
    if op.seq <= rules.mission.report_seqs.get(op.robot, 0):
        return Change([], [], {}, None, True)
    rules.task(op.robot)
    return Change([ev.ReportSeq(robot=op.robot, seq=op.seq)], [], {}, None)


RULES: dict[type[Any], Rule] = {
    Sync: sync,
    Unsync: unsync,
    Control: control,
    Retry: retry,
    Cancel: cancel,
    UplinkSent: uplink_sent,
    UplinkSettle: uplink_settle,
    Answer: answer,
    Reconcile: reconcile,
    DownlinkRefused: downlink_refused,
}
