"""Operation rules: the one place that decides what may change in a mission.

Pure Python, no transport. `Engine.submit` applies an operation atomically or
refuses it with a `Refusal` (a stable code and a sentence naming robot, skill
and reason); an applied operation yields the small events describing it and
bumps the revision by one.

Each operation type has one rule (the registry `RULES`), in the module of its
family: `edit` (skills of the plan), `barriers`, `markers`, `execution` (the
robots' answers and reports), `waivers` (of plan checks); whole missions
(load, new) are here, with what the engine keeps per client: remembered
requests and undo/redo histories.

Operations that involve a robot (sync, unsync, run, pause, stop, reset,
retry) add a command to the robot's uplink and return (`uplink`); the
robot's answer and reports are submitted like any operation. Tools and tests
that play the robot themselves may use the direct path instead: `plan_sync`,
`plan_unsync`, `plan_control`, `plan_retry`, then `SyncAck`, `UnsyncDone`,
`RetryAck`, and `release` (see `execution`).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Container, Iterable
from typing import Any, NamedTuple, Protocol

from backend.core import events as ev
from backend.core.checks import check_mission, resolve_shorthands
from backend.core.library import Library
from backend.core.model import FINISHED, Mission, SkillInstance, Status, format_path
from backend.core.ops import (
    UNDOABLE,
    AddBarrier,
    AddRobot,
    AddSkill,
    Control,
    DeleteSkills,
    EditBarrier,
    EditSkill,
    LoadMission,
    MarkerDelete,
    MarkerMove,
    MarkerRename,
    MoveSkill,
    NewMission,
    Operation,
    Reassign,
    Redo,
    RemoveBarrier,
    RestoreMarker,
    RetireRobot,
    Retry,
    ReturnSkills,
    SetSkill,
    Sync,
    Undo,
    Unsync,
)
from backend.core.rules import (
    barriers,
    edit,
    execution,
    markers,
    questions,
    reassign,
    team,
    uplink,
    waivers,
)
from backend.core.rules.base import Applied, Change, Offers, Refusal, Rule, Rules

__all__ = ["RULES", "Applied", "Engine", "Offers", "Origin", "Recorder", "Refusal"]

REMEMBERED_REQUESTS = 10_000
UNDO_DEPTH = 100

# an operation that reverts another: (that operation, what it reverted, the
# revision it was made at)
HistoryEntry = tuple[Operation, str, int]
History = dict[str, list[HistoryEntry]]  # client -> its entries, oldest first


# -- whole missions ------------------------------------------------------------


def load_mission(rules: Rules, op: LoadMission) -> Change:
    _check_replaceable(rules)
    new = op.mission.copy_deep()
    resolve_shorthands(new, rules.library)
    problems = check_mission(new, rules.library)
    if problems:
        path, msg = problems[0]
        raise Refusal("bad_mission", f"the mission is invalid at {format_path(path)}: {msg}")
    reset, dissolved = ([], []) if op.keep_state else as_plan(new)
    _take_over(new, rules.mission)
    notes = []
    if reset:
        notes.append(
            f"loaded as a plan: {', '.join(reset)} idle again (the file had them synchronized; "
            "what the robots hold is theirs to say)"
        )
    if dissolved:
        notes.append(
            f"barrier {', '.join(dissolved)} dissolved: a finished skill and an idle one "
            "never start together"
        )
    value = {"reset": reset, "dissolved": dissolved}
    return Change([ev.MissionReplaced(mission=new)], notes, value, None)


def as_plan(m: Mission) -> tuple[list[str], list[str]]:
    """`m` as a plan, in place: every skill that is not finished is idle
    (finished ones stay: the log); a barrier left with a finished skill and
    an idle one is dissolved. Returns the skills reset and the barriers
    dissolved."""
    reset = _reset_to_idle(m)
    dissolved = [
        bid for bid, b in m.barriers.items() if len({_finished(m, sid) for sid in b.skills}) > 1
    ]
    for bid in dissolved:
        del m.barriers[bid]
    return reset, dissolved


def _reset_to_idle(m: Mission) -> list[str]:
    """Makes every skill that is on a robot (not idle, not finished) idle;
    returns their ids."""
    reset: list[str] = []
    for task in m.tasks.values():
        for s in task:
            if s.status not in FINISHED and s.status != Status.IDLE:
                reset.append(s.id)
                s.status, s.status_info, s.started_at = Status.IDLE, "", None
    return reset


def _finished(m: Mission, sid: str) -> bool:
    found = m.find(sid)
    return found is not None and found[2].status in FINISHED


def _check_replaceable(rules: Rules) -> None:
    """Refused while a robot holds or is being sent part of the mission."""
    busy = _in_flight(rules)
    if busy:
        busy_text = ", ".join(busy)
        raise Refusal(
            "robot_busy",
            f"cannot replace the mission while commands are in flight: {busy_text}; "
            "try again when they end (or cancel them)",
        )
    held = [r for r, t in rules.mission.tasks.items() if _holds(t)]
    if held:
        raise Refusal(
            "robots_busy",
            f"cannot replace the mission while {', '.join(held)} hold synchronized skills; "
            "reset them first",
        )


def _in_flight(rules: Rules) -> list[str]:
    """The commands in flight, as `robot (what)`: the rules' pending ones,
    then the mission's uplink commands."""
    return [f"{r} ({what})" for r, what in rules.pending.items()] + [
        f"{c.robot} ({c.title()}, {c.state.value})" for c in rules.mission.pending_commands()
    ]


def _holds(task: list[SkillInstance]) -> bool:
    """A robot holds skills of its task (synchronized, queued or active)."""
    return any(s.status not in FINISHED and s.status != Status.IDLE for s in task)


def _take_over(new: Mission, old: Mission) -> None:
    """What a replacing mission keeps of the one it replaces."""
    new.revision = old.revision
    new.library = old.library  # the server's library stays; the file's path was relative to it
    # everything in the new mission counts as changed now (stale edits of
    # the old mission are refused)
    stamp = old.revision + 1
    for task in new.tasks.values():
        for sk in task:
            sk.rev = stamp
    new.task_revs = dict.fromkeys(new.robots, stamp)
    new.marker_revs = dict.fromkeys(new.markers, stamp)
    new.next_skill = max(new.next_skill, old.next_skill)
    new.next_barrier = max(new.next_barrier, old.next_barrier)
    new.report_seqs = dict(old.report_seqs)
    # robots apply commands by their sequence numbers: they go on across missions
    new.uplink = {r: [c.model_copy() for c in cmds] for r, cmds in old.uplink.items()}
    new.uplink_seqs = dict(old.uplink_seqs)
    new.next_command = max(new.next_command, old.next_command)
    new.next_question = max(new.next_question, old.next_question)  # never one number twice
    for robot in new.robots:
        new.tasks.setdefault(robot, [])


def new_mission(rules: Rules, op: NewMission) -> Change:
    empty = Mission(
        name=op.name,
        library=rules.mission.library,
        robots=rules.mission.robots,
        tasks={r: [] for r in rules.mission.robots},
    )
    return load_mission(rules, LoadMission(mission=empty))


# operation type -> its rule (undo and redo are the engine's: they replay a
# client's history through these rules)
RULES: dict[type[Any], Rule] = {
    **edit.RULES,
    **barriers.RULES,
    **markers.RULES,
    **execution.RULES,
    **uplink.RULES,
    **waivers.RULES,
    **team.RULES,
    **reassign.RULES,
    **questions.RULES,
    LoadMission: load_mission,
    NewMission: new_mission,
}


# -- optimistic concurrency ----------------------------------------------------


def _touched(m: Mission, op: Operation) -> list[tuple[int, str]]:
    """(revision of its last change, name for a person) of what `op` touches."""
    return _TOUCHED.get(type(op), _untouched)(m, op)


def _untouched(m: Mission, op: Any) -> list[tuple[int, str]]:
    return []


def _list_touched(m: Mission, op: AddSkill | Unsync) -> list[tuple[int, str]]:
    return [_task_rev(m, op.robot)]


def _sync_touched(m: Mission, op: Sync) -> list[tuple[int, str]]:
    """The list, and the skill it synchronizes through."""
    return [_task_rev(m, op.robot), *_skill_revs(m, [op.through] if op.through else [])]


def _skills_touched(m: Mission, op: DeleteSkills | AddBarrier) -> list[tuple[int, str]]:
    return _skill_revs(m, op.ids)


def _skill_touched(m: Mission, op: EditSkill | Retry | SetSkill) -> list[tuple[int, str]]:
    return _skill_revs(m, [op.id])


def _move_touched(m: Mission, op: MoveSkill) -> list[tuple[int, str]]:
    """The skill, and the list it is in."""
    found = m.find(op.id)
    return _skill_revs(m, [op.id]) + ([_task_rev(m, found[0])] if found else [])


def _barrier_touched(m: Mission, op: RemoveBarrier | EditBarrier) -> list[tuple[int, str]]:
    """The skills the barrier holds."""
    b = m.barriers.get(op.barrier)
    return _skill_revs(m, b.skills if b is not None else [])


def _marker_touched(
    m: Mission, op: MarkerMove | MarkerRename | MarkerDelete | RestoreMarker
) -> list[tuple[int, str]]:
    return [(m.marker_revs.get(op.name, 0), f"marker {op.name}")]


def _robot_touched(m: Mission, op: AddRobot | RetireRobot) -> list[tuple[int, str]]:
    """A robot joining or retiring: its entry and list (an add or retire stamps it)."""
    return [_task_rev(m, op.name)]


def _reassign_touched(m: Mission, op: Reassign) -> list[tuple[int, str]]:
    """The skills named, the plan given away and the list they go to."""
    lists = dict.fromkeys((op.from_robot or op.to, op.to))  # the plan given, and its target
    return _skill_revs(m, op.ids) + [_task_rev(m, r) for r in lists]


def _return_touched(m: Mission, op: ReturnSkills) -> list[tuple[int, str]]:
    """The skills given back and the partners renamed (an undo must not
    overwrite a later edit of them)."""
    return _skill_revs(m, [it.skill.id for it in op.items] + list(op.partners))


# operation type -> what it touches; the others touch nothing a client saw
_TOUCHED: dict[type[Any], Callable[[Mission, Any], list[tuple[int, str]]]] = {
    AddSkill: _list_touched,
    Unsync: _list_touched,
    Sync: _sync_touched,
    DeleteSkills: _skills_touched,
    AddBarrier: _skills_touched,
    MoveSkill: _move_touched,
    EditSkill: _skill_touched,
    Retry: _skill_touched,
    SetSkill: _skill_touched,
    RemoveBarrier: _barrier_touched,
    EditBarrier: _barrier_touched,
    MarkerMove: _marker_touched,
    MarkerRename: _marker_touched,
    MarkerDelete: _marker_touched,
    RestoreMarker: _marker_touched,
    AddRobot: _robot_touched,
    RetireRobot: _robot_touched,
    Reassign: _reassign_touched,
    ReturnSkills: _return_touched,
}


def _task_rev(m: Mission, robot: str) -> tuple[int, str]:
    return m.task_revs.get(robot, 0), f"the list of {robot}"


def _skill_revs(m: Mission, ids: Iterable[str]) -> list[tuple[int, str]]:
    found = [m.find(sid) for sid in ids]
    return [(f[2].rev, f"skill {f[2].display()}") for f in found if f]


class Origin(NamedTuple):
    """What a batch comes from: the operation submitted and who sent it."""

    op: Operation
    client: str = ""
    request_id: str | None = None
    actor: str = ""  # who, as the journal says it (`user@client`, a robot, "server")


class Recorder(Protocol):
    """Where the engine writes each batch before it changes the mission (the
    server's journal). If it raises, the operation changes nothing."""

    def record(self, batch: ev.EventBatch, origin: Origin) -> None: ...


class Engine(Rules):
    """The rules with what they need to be applied: the revision, the
    requests already answered, each client's undo and redo history, and
    the recorder every batch goes to first (none: nothing is recorded)."""

    def __init__(
        self,
        mission: Mission,
        library: Library,
        *,
        recorder: Recorder | None = None,
        offers: Offers | None = None,
        default_expiry_s: float | None = None,
    ):
        super().__init__(mission, library, offers=offers, default_expiry_s=default_expiry_s)
        self.recorder = recorder
        self.requests: OrderedDict[tuple[str, str], Applied] = OrderedDict()
        # client -> [(operation that reverts, what it reverts, revision made at)]
        self.undo_stack: History = {}
        self.redo_stack: History = {}
        # client -> revisions its own edits made (undo may revert over them),
        # oldest first: a dict used as an ordered set, so trimming is O(1)
        self.own_revs: dict[str, dict[int, None]] = {}

    # -- entry point -----------------------------------------------------
    def submit(
        self,
        op: Operation,
        *,
        client: str = "",
        request_id: str | None = None,
        expected_revision: int | None = None,
        actor: str = "",
    ) -> Applied:
        """Apply one operation atomically, or raise Refusal (nothing changes).
        A request applied already (`client`, `request_id`) gets its first
        answer again, marked `duplicate`; nothing is applied twice."""
        if request_id is not None:
            done = self.requests.get((client, request_id))
            if done is not None:
                return Applied(done.revision, [], done.notes, done.value, duplicate=True)
        if expected_revision is not None:
            self.check_fresh(op, expected_revision)
        applied = self._run(Origin(op, client, request_id, actor or client))
        if request_id is not None:
            self.remember(client, request_id, applied)
        return applied

    def _run(self, origin: Origin) -> Applied:
        """Undo and redo walk the client's history; any other operation applies its rule."""
        if isinstance(origin.op, Undo):
            return self._revert(origin, self.undo_stack, self.redo_stack, "undo")
        if isinstance(origin.op, Redo):
            return self._revert(origin, self.redo_stack, self.undo_stack, "redo")
        return self._apply(origin)

    def _apply(self, origin: Origin) -> Applied:
        op, client = origin.op, origin.client
        self.actor = origin.actor
        change = rule_for(op)(self, op)
        applied = self._commit(origin, change.events, change.notes, change.value, change.duplicate)
        applied.alerts = list(change.alerts)
        if change.undo is not None and isinstance(op, UNDOABLE) and applied.events:
            self._push_undo(client, change.undo, op.op, applied.revision)
            self._mine(client, applied.revision)
        return applied

    def remember(self, client: str, request_id: str, applied: Applied) -> None:
        self.requests[(client, request_id)] = applied
        while len(self.requests) > REMEMBERED_REQUESTS:
            self.requests.popitem(last=False)

    def _commit(
        self,
        origin: Origin,
        events: list[ev.Event],
        notes: list[str],
        value: dict[str, Any],
        duplicate: bool = False,
    ) -> Applied:
        if not events:  # nothing changed: no new revision
            return Applied(self.mission.revision, [], notes, value, duplicate=duplicate)
        revision = self.mission.revision + 1
        batch = ev.EventBatch(revision=revision, events=events)
        if self.recorder is not None:
            self.recorder.record(batch, origin)
        self.mission = ev.apply_events(self.mission, batch)
        if any(isinstance(e, ev.MissionReplaced) for e in events):
            # applied, not just asked: histories end
            self.undo_stack.clear()
            self.redo_stack.clear()
        return Applied(revision, events, notes, value)

    def check_fresh(self, op: Operation, seen: int, mine: Container[int] = frozenset()) -> None:
        """Optimistic concurrency: refuse if what the operation touches changed
        after the revision the client saw (changes at revisions in `mine`, the
        client's own, do not count)."""
        for rev, what in _touched(self.mission, op):
            if rev > seen and rev not in mine:
                raise Refusal(
                    "stale",
                    f"{what} changed at revision {rev}, after the revision {seen} you saw; "
                    "reload and try again",
                )

    # -- commands to robots (see execution) --------------------------------------
    def plan_sync(self, op: Sync) -> list[SkillInstance]:
        """Skills to send to the robot; they are locked until `release` or the
        robot's `SyncAck`."""
        return execution.plan_sync(self, op, uplink.sync_skills)

    def plan_unsync(self, op: Unsync) -> list[str]:
        return execution.plan_unsync(self, op)

    def plan_control(self, op: Control) -> list[str]:
        """Robots the command goes to; refused when it applies to none."""
        return execution.plan_control(self, op)

    def plan_retry(self, op: Retry) -> SkillInstance:
        return execution.plan_retry(self, op)

    def release(self, robot: str, ids: Iterable[str] = ()) -> None:
        """The command to `robot` ended (answered, refused or timed out)."""
        execution.release(self, robot, ids)

    def barrier_partners(self, skill_id: str) -> list[tuple[str, str]]:
        """(robot, skill id) of the other members of a skill's barrier."""
        return barriers.barrier_partners(self, skill_id)

    # -- undo / redo -------------------------------------------------------------
    def _mine(self, client: str, revision: int) -> None:
        own = self.own_revs.setdefault(client, {})
        own[revision] = None  # revisions only grow: the first one is the oldest
        if len(own) > 4 * UNDO_DEPTH:
            del own[next(iter(own))]

    def _push_undo(self, client: str, inverse: Operation, what: str, revision: int) -> None:
        stack = self.undo_stack.setdefault(client, [])
        stack.append((inverse, what, revision))
        del stack[:-UNDO_DEPTH]
        self.redo_stack.pop(client, None)  # a new edit starts a new future

    def _revert(self, origin: Origin, source: History, target: History, verb: str) -> Applied:
        """Apply the client's last entry of `source` (undo or redo history);
        what reverts it goes to `target`."""
        client = origin.client
        stack = source.get(client) or []
        if not stack:
            raise Refusal(
                f"nothing_to_{verb}",
                f"nothing to {verb} (only your own edits of unsynchronized skills, barriers "
                "and markers can be undone)",
            )
        inverse, what, made_at = stack.pop()
        change = self._checked_inverse(client, inverse, what, made_at, verb)
        done = "undone" if verb == "undo" else "redone"
        try:
            applied = self._commit(
                origin, change.events, change.notes, {**change.value, done: what}
            )
        except Exception:  # not applied (the journal refused it): still to do
            stack.append((inverse, what, made_at))
            raise
        self._mine(client, applied.revision)
        if change.undo is not None:
            target.setdefault(client, []).append((change.undo, what, applied.revision))
        return applied

    def _checked_inverse(
        self, client: str, inverse: Operation, what: str, made_at: int, verb: str
    ) -> Change:
        """What `inverse` changes, refused (and so dropped from the history) if
        its rule refuses it or someone else changed what it touches since."""
        try:
            change = rule_for(inverse)(self, inverse)
            try:
                self.check_fresh(inverse, made_at, self.own_revs.get(client, frozenset()))
            except Refusal as r:  # do not overwrite someone else's later edit
                raise Refusal(
                    "stale",
                    f"another client changed it since ({r.message.split(' changed at')[0]})",
                ) from None
        except Refusal as r:
            raise Refusal(
                r.code,
                f"cannot {verb} {what} (dropped from your history): {r.message}",
                robot=r.robot,
                skill=r.skill,
            ) from None
        return change


def rule_for(op: Operation) -> Rule:
    """The rule of an operation; refused for the ones planned, not submitted."""
    rule = RULES.get(type(op))
    if rule is None:
        plan = "plan_control" if op.op in ("run", "pause", "stop", "reset") else f"plan_{op.op}"
        raise Refusal("bad_request", f"'{op.op}' is planned with {plan}(), not submitted")
    return rule
