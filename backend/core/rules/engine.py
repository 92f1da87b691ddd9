"""Operation rules: the one place that decides what may change in a mission.

Pure Python, no transport. `Engine.submit` applies an operation atomically or
refuses it with a `Refusal` (a stable code and a sentence naming robot, skill
and reason); an applied operation yields the small events describing it and
bumps the revision by one.

Operations that involve a robot are two-phase: `plan_sync`, `plan_unsync`,
`plan_control` and `plan_retry` check and say what to send, without changing
the mission; the robot's answer (`SyncAck`, `UnsyncDone`, `RetryAck`,
`Report`) is then submitted like any operation.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Container
from dataclasses import dataclass, field
from typing import Any

from backend.core import events as ev
from backend.core.checks import check_mission, resolve_shorthands
from backend.core.library import Library, check_params
from backend.core.model import (
    ACTIVE,
    FINISHED,
    TRANSITIONS,
    Barrier,
    Mission,
    SkillInstance,
    Status,
    how_to_change,
)
from backend.core.ops import (
    UNDOABLE,
    AddBarrier,
    AddSkill,
    Control,
    DeleteSkills,
    EditSkill,
    LoadMission,
    MarkerAdd,
    MarkerDelete,
    MarkerMove,
    MarkerRename,
    MoveSkill,
    NewMission,
    Reconcile,
    Redo,
    RemoveBarrier,
    Report,
    RestoreBarrier,
    RestoreItem,
    RestoreMarker,
    RestoreSkills,
    Retry,
    RetryAck,
    SetSkill,
    Sync,
    SyncAck,
    Undo,
    Unsync,
    UnsyncDone,
)

REMEMBERED_REQUESTS = 10_000
UNDO_DEPTH = 100
MAX_PROBLEMS = 5  # parameter problems named in one refusal


class Refusal(Exception):
    """An operation that would break a rule. `code` is stable; `message` is a
    sentence for a person."""

    def __init__(
        self,
        code: str,
        message: str,
        *,
        robot: str | None = None,
        skill: str | None = None,
        param: str | None = None,
    ):
        super().__init__(message)
        self.code = code
        self.message = message
        self.robot = robot
        self.skill = skill
        self.param = param

    def to_dict(self) -> dict[str, Any]:
        d = {"code": self.code, "message": self.message}
        for k in ("robot", "skill", "param"):
            if getattr(self, k) is not None:
                d[k] = getattr(self, k)
        return d


@dataclass
class Applied:
    revision: int
    events: list[Any] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)  # e.g. skills still using an old marker value
    value: dict[str, Any] = field(default_factory=dict)  # e.g. {"id": "lru1-7"}
    duplicate: bool = False  # a retried request, applied before

    def batch(self, actor: str = "", op: str = "") -> ev.EventBatch:
        return ev.EventBatch(revision=self.revision, events=self.events, actor=actor, op=op)


class Engine:
    def __init__(self, mission: Mission, library: Library):
        self.mission = mission
        self.library = library
        # skill id -> why it cannot be edited now (a sync is in flight)
        self.locked: dict[str, str] = {}
        # robot -> the command in flight to it (one at a time per robot)
        self.pending: dict[str, str] = {}
        self.requests: OrderedDict[tuple[str, str], Applied] = OrderedDict()
        # client -> [(operation that reverts, what it reverts, revision made at)]
        self.undo_stack: dict[str, list[tuple[Any, str, int]]] = {}
        self.redo_stack: dict[str, list[tuple[Any, str, int]]] = {}
        # skill id -> parameter values sent with an in-flight sync
        self.sent: dict[str, dict[str, Any]] = {}
        # client -> revisions its own edits made (undo may revert over them),
        # oldest first: a dict used as an ordered set, so trimming is O(1)
        self.own_revs: dict[str, dict[int, None]] = {}
        # called with each batch before it changes the mission (the server
        # journals it there): if it raises, the operation changes nothing
        self.before_apply: Callable[[ev.EventBatch], None] | None = None

    # -- entry point -----------------------------------------------------
    def submit(
        self,
        op: Any,
        *,
        client: str = "",
        request_id: str | None = None,
        expected_revision: int | None = None,
    ) -> Applied:
        """Apply one operation atomically, or raise Refusal (nothing changes)."""
        if request_id is not None:
            done = self.requests.get((client, request_id))
            if done is not None:
                return Applied(done.revision, [], done.notes, done.value, duplicate=True)
        if expected_revision is not None:
            self.check_fresh(op, expected_revision)
        handler = getattr(self, f"_op_{op.op}", None)
        if handler is None:
            plan = "plan_control" if op.op in ("run", "pause", "stop", "reset") else f"plan_{op.op}"
            raise Refusal("bad_request", f"'{op.op}' is planned with {plan}(), not submitted")
        result = handler(op, client)
        if isinstance(result, Applied):
            applied = result
        else:
            events, notes, value, undo = result
            applied = self._commit(events, notes, value)
            if undo is not None and isinstance(op, UNDOABLE) and applied.events:
                self._push_undo(client, undo, op.op, applied.revision)
                self._mine(client, applied.revision)
        if request_id is not None:
            self.remember(client, request_id, applied)
        return applied

    def remember(self, client: str, request_id: str, applied: Applied) -> None:
        self.requests[(client, request_id)] = applied
        while len(self.requests) > REMEMBERED_REQUESTS:
            self.requests.popitem(last=False)

    def _commit(self, events: list, notes: list[str], value: dict) -> Applied:
        if not events:  # nothing changed: no new revision
            return Applied(self.mission.revision, [], notes, value)
        revision = self.mission.revision + 1
        batch = ev.EventBatch(revision=revision, events=events)
        if self.before_apply is not None:
            self.before_apply(batch)
        self.mission = ev.apply_events(self.mission, batch)
        if any(
            isinstance(e, ev.MissionReplaced) for e in events
        ):  # applied, not just asked: histories end
            self.undo_stack.clear()
            self.redo_stack.clear()
        return Applied(revision, events, notes, value)

    # -- lookups ---------------------------------------------------------
    def robot_type(self, robot: str) -> str:
        spec = self.mission.robots.get(robot)
        if spec is None:
            known = ", ".join(self.mission.robots) or "none"
            raise Refusal(
                "unknown_robot",
                f"no robot '{robot}' in this mission (robots: {known})",
                robot=robot,
            )
        return spec.type

    def skill(self, skill_id: str) -> tuple[str, int, SkillInstance]:
        found = self.mission.find(skill_id)
        if found is None:
            raise Refusal(
                "unknown_skill", f"no skill with id '{skill_id}' in this mission", skill=skill_id
            )
        return found

    def task(self, robot: str) -> list[SkillInstance]:
        self.robot_type(robot)
        return self.mission.tasks.setdefault(robot, [])

    @staticmethod
    def first_idle(task: list[SkillInstance]) -> int:
        for i, s in enumerate(task):
            if s.status == Status.IDLE:
                return i
        return len(task)

    @staticmethod
    def first_queued(task: list[SkillInstance]) -> int | None:
        for i, s in enumerate(task):
            if s.status == Status.IDLE_SYNCHRONIZED:
                return i
        return None

    @staticmethod
    def active(task: list[SkillInstance]) -> SkillInstance | None:
        for s in task:
            if s.status in ACTIVE:
                return s
        return None

    def _outside_locked(self, robot: str, task: list[SkillInstance], index: int) -> None:
        """Skills being synchronized stay at the head of the unsynchronized
        section until the robot answers: nothing may be put before them."""
        locked_after = [s.id for s in task[index:] if s.id in self.locked]
        if locked_after:
            raise Refusal(
                "locked",
                f"cannot place a skill before {', '.join(locked_after)}: being synchronized to {robot}",
                robot=robot,
            )

    def _editable(self, robot: str, s: SkillInstance, doing: str) -> None:
        if s.status != Status.IDLE:
            raise Refusal(
                "not_idle",
                f"cannot {doing} {s.display()} on {robot}: it is {s.status.value}; only idle "
                f"(unsynchronized) skills can change — {how_to_change(s.status)}",
                robot=robot,
                skill=s.id,
            )
        if s.id in self.locked:
            raise Refusal(
                "locked",
                f"cannot {doing} {s.display()} on {robot}: {self.locked[s.id]}",
                robot=robot,
                skill=s.id,
            )

    def check_fresh(self, op: Any, seen: int, mine: Container[int] = frozenset()) -> None:
        """Optimistic concurrency: refuse if what the operation touches changed
        after the revision the client saw (changes at revisions in `mine`, the
        client's own, do not count)."""
        m = self.mission
        revs: list[tuple[int, str]] = []

        def skill_rev(sid: str) -> None:
            found = m.find(sid)
            if found:
                revs.append((found[2].rev, f"skill {found[2].display()}"))

        def task_rev(robot: str | None) -> None:
            if robot is not None:
                revs.append((m.task_revs.get(robot, 0), f"the list of {robot}"))

        match op:
            case AddSkill(robot=r) | Unsync(robot=r):
                task_rev(r)
            case Sync(robot=r, through=t):
                task_rev(r)
                if t:
                    skill_rev(t)
            case DeleteSkills(ids=ids) | AddBarrier(ids=ids):
                for sid in ids:
                    skill_rev(sid)
            case MoveSkill(id=sid):
                skill_rev(sid)
                found = m.find(sid)
                task_rev(found[0] if found else None)
            case EditSkill(id=sid) | Retry(id=sid) | SetSkill(id=sid):
                skill_rev(sid)
            case RemoveBarrier(barrier=bid):
                for sid in m.barriers[bid].skills if bid in m.barriers else []:
                    skill_rev(sid)
            case (
                MarkerMove(name=n)
                | MarkerRename(name=n)
                | MarkerDelete(name=n)
                | RestoreMarker(name=n)
            ):
                revs.append((m.marker_revs.get(n, 0), f"marker {n}"))
        for rev, what in revs:
            if rev > seen and rev not in mine:
                raise Refusal(
                    "stale",
                    f"{what} changed at revision {rev}, after the revision {seen} you saw; "
                    "reload and try again",
                )

    # -- editing the unsynchronized section -------------------------------
    def _check_params(
        self, robot: str, skill: str, params: dict, bindings: dict, skill_id: str | None = None
    ):
        rtype = self.robot_type(robot)
        who = f"{skill_id} ({skill})" if skill_id else skill
        if self.library.skill_for(rtype, skill) is None:
            offered = ", ".join(self.library.skills_of(rtype)) or "none"
            raise Refusal(
                "unknown_skill_type",
                f"robot {robot} ({rtype}) has no skill '{skill}' (it offers: {offered})",
                robot=robot,
            )
        out, problems = check_params(
            self.library,
            rtype,
            skill,
            params,
            bindings,
            markers=self.mission.markers,
            robots=set(self.mission.robots),
        )
        if problems:
            # every problem: a missing parameter listed first must not hide a bad value
            said = "; ".join(
                f"parameter {'.'.join(str(x) for x in q.path)}: {q.message}"
                for q in problems[:MAX_PROBLEMS]
            )
            more = (
                f" (and {len(problems) - MAX_PROBLEMS} more)"
                if len(problems) > MAX_PROBLEMS
                else ""
            )
            p = problems[0]
            raise Refusal(
                "bad_param",
                f"{robot}, skill {who}, {said}{more}",
                robot=robot,
                skill=skill_id,
                param=str(p.path[0]) if p.path else None,
            )
        return out

    def _op_add(self, op: AddSkill, client: str):
        task = self.task(op.robot)
        params = self._check_params(op.robot, op.skill, op.params, op.bindings)
        start = self.first_idle(task)
        n_idle = len(task) - start
        at = n_idle if op.at is None else op.at
        if not 0 <= at <= n_idle:
            raise Refusal(
                "bad_index",
                f"position {at} is outside {op.robot}'s unsynchronized section (0..{n_idle})",
                robot=op.robot,
            )
        self._outside_locked(op.robot, task, start + at)
        n = self.mission.next_skill
        while (
            self.mission.find(f"{op.robot}-{n}") is not None
        ):  # ids from files may use any numbers
            n += 1
        sid = f"{op.robot}-{n}"
        skill = SkillInstance(
            id=sid,
            skill=op.skill,
            label=op.label,
            params=params,
            bindings=dict(op.bindings),
            policies=op.policies or SkillInstance.model_fields["policies"].default_factory(),
        )
        events = [ev.SkillAdded(robot=op.robot, index=start + at, skill=skill)]
        return events, [], {"id": sid}, DeleteSkills(ids=[sid])

    def _delete_events(self, ids: list[str], doing: str = "delete") -> tuple[list, RestoreSkills]:
        m = self.mission
        items: list[RestoreItem] = []
        for sid in dict.fromkeys(ids):
            robot, i, s = self.skill(sid)
            self._editable(robot, s, doing)
            items.append(RestoreItem(robot=robot, index=i, skill=s))
        gone = {it.skill.id for it in items}
        events: list = []
        barriers_before: dict[str, Barrier] = {}
        for bid, b in m.barriers.items():
            if not gone & set(b.skills):
                continue
            rest = [sid for sid in b.skills if sid not in gone]
            for sid in rest:
                robot, _, partner = self.skill(sid)
                if partner.status != Status.IDLE and partner.status not in FINISHED:
                    raise Refusal(
                        "barrier_partner_synchronized",
                        f"cannot {doing} {', '.join(sorted(gone & set(b.skills)))}: barrier {bid} ties it to "
                        f"{partner.display()}, already on {robot}; unsynchronize {partner.id} first",
                        robot=robot,
                        skill=partner.id,
                    )
            barriers_before[bid] = b
            robots_left = {m.find(sid)[0] for sid in rest}
            if len(robots_left) >= 2:
                events.append(ev.BarrierSet(id=bid, barrier=Barrier(skills=rest)))
            else:
                events.append(ev.BarrierRemoved(id=bid))
        # remove from the highest index down so the recorded indices stay valid to restore
        for it in sorted(items, key=lambda it: (it.robot, -it.index)):
            events.insert(0, ev.SkillRemoved(robot=it.robot, id=it.skill.id))
        restore = RestoreSkills(
            items=sorted(items, key=lambda it: (it.robot, it.index)), barriers=barriers_before
        )
        return events, restore

    def _op_delete(self, op: DeleteSkills, client: str):
        events, restore = self._delete_events(op.ids)
        return events, [], {}, restore

    def _op_restore_skills(self, op: RestoreSkills, client: str):
        events: list = []
        sizes: dict[str, int] = {}
        for it in sorted(op.items, key=lambda it: (it.robot, it.index)):
            if self.mission.find(it.skill.id) is not None:
                raise Refusal("exists", f"skill {it.skill.id} exists already", skill=it.skill.id)
            task = self.task(it.robot)
            sizes.setdefault(it.robot, len(task))
            # ascending indices: each insert lands where the skill was, unless
            # the synchronized section has grown since
            idx = min(max(it.index, self.first_idle(task)), sizes[it.robot])
            self._outside_locked(it.robot, task, min(idx, len(task)))
            sizes[it.robot] += 1
            bindings = {k: v for k, v in it.skill.bindings.items() if v in self.mission.markers}
            try:  # markers may have moved since: take their current values
                params = self._check_params(
                    it.robot, it.skill.skill, it.skill.params, bindings, skill_id=it.skill.id
                )
            except Refusal:
                params, bindings = it.skill.params, {}
            skill = it.skill.model_copy(
                update={"status": Status.IDLE, "params": params, "bindings": bindings}
            )
            events.append(ev.SkillAdded(robot=it.robot, index=idx, skill=skill))
        restored = {it.skill.id for it in op.items}
        for bid, b in op.barriers.items():
            for sid in b.skills:
                if sid in restored:
                    continue
                robot, _, partner = self.skill(sid)
                other = self.mission.barrier_of(sid)
                if partner.status != Status.IDLE or other not in (None, bid):
                    raise Refusal(
                        "barrier_invalid",
                        f"cannot restore barrier {bid}: its partner {partner.display()} on {robot} has changed since",
                        robot=robot,
                        skill=sid,
                    )
            events.append(ev.BarrierSet(id=bid, barrier=b))
        return events, [], {}, DeleteSkills(ids=[it.skill.id for it in op.items])

    def _op_move(self, op: MoveSkill, client: str):
        robot, i, s = self.skill(op.id)
        self._editable(robot, s, "move")
        task = self.task(robot)
        start = self.first_idle(task)
        n_idle = len(task) - start
        if not 0 <= op.index < n_idle:
            raise Refusal(
                "bad_index",
                f"position {op.index} is outside {robot}'s unsynchronized section (0..{n_idle - 1})",
                robot=robot,
                skill=op.id,
            )
        if start + op.index == i:
            return [], [], {}, None
        self._outside_locked(robot, task, min(start + op.index, i))
        return (
            [ev.SkillMoved(robot=robot, id=op.id, index=start + op.index)],
            [],
            {},
            MoveSkill(id=op.id, index=i - start),
        )

    def _op_edit(self, op: EditSkill, client: str):
        robot, _, s = self.skill(op.id)
        self._editable(robot, s, "edit")
        params = dict(s.params)
        bindings = dict(s.bindings)
        for name, value in op.params.items():
            params[name] = value
            bindings.pop(name, None)  # a typed value replaces a marker binding
        for name, marker in op.bindings.items():
            if marker is None:
                bindings.pop(name, None)
            else:
                bindings[name] = marker
        new = SetSkill(
            id=s.id,
            label=s.label if op.label is None else op.label,
            params=params,
            bindings=bindings,
            policies=op.policies or s.policies,
        )
        return self._op_set_skill(new, client)

    def _op_set_skill(self, op: SetSkill, client: str):
        robot, _, s = self.skill(op.id)
        self._editable(robot, s, "edit")
        if not op.bindings and not s.bindings and op.params == s.params:
            # checked when they were set (e.g. only the label changes); bound
            # ones are re-resolved below, as a marker may have moved since
            params = s.params
        else:
            params = self._check_params(robot, s.skill, op.params, op.bindings, skill_id=s.id)
        changes: dict[str, Any] = {}
        if op.label != s.label:
            changes["label"] = op.label
        if params != s.params:
            changes["params"] = params
        if op.bindings != s.bindings:
            changes["bindings"] = op.bindings
        if op.policies != s.policies:
            changes["policies"] = op.policies.model_dump()
        if not changes:
            return [], [], {}, None
        old = SetSkill(
            id=s.id, label=s.label, params=s.params, bindings=s.bindings, policies=s.policies
        )
        return [ev.SkillChanged(id=s.id, changes=changes)], [], {}, old

    # -- barriers ----------------------------------------------------------
    def _op_barrier(self, op: AddBarrier, client: str):
        m = self.mission
        robots: dict[str, str] = {}
        for sid in op.ids:
            robot, _, s = self.skill(sid)
            if s.status != Status.IDLE:
                raise Refusal(
                    "not_idle",
                    f"cannot put {s.display()} on {robot} in a barrier: it is {s.status.value}; barriers join idle skills",
                    robot=robot,
                    skill=sid,
                )
            if sid in self.locked:
                raise Refusal(
                    "locked",
                    f"cannot put {s.display()} in a barrier: {self.locked[sid]}",
                    robot=robot,
                    skill=sid,
                )
            if robot in robots:
                raise Refusal(
                    "barrier_invalid",
                    f"skills {robots[robot]} and {sid} both belong to {robot}; a barrier takes one skill per robot",
                    robot=robot,
                    skill=sid,
                )
            robots[robot] = sid
            other = m.barrier_of(sid)
            if other is not None:
                raise Refusal(
                    "barrier_invalid",
                    f"{s.display()} on {robot} is already in barrier {other}",
                    robot=robot,
                    skill=sid,
                )
        if len(robots) < 2:
            raise Refusal("barrier_invalid", "a barrier needs skills of at least two robots")
        n = m.next_barrier
        while f"b{n}" in m.barriers:
            n += 1
        bid = f"b{n}"
        return (
            [ev.BarrierSet(id=bid, barrier=Barrier(skills=list(op.ids)))],
            [],
            {"barrier": bid},
            RemoveBarrier(barrier=bid),
        )

    def _op_restore_barrier(self, op: RestoreBarrier, client: str):
        if op.barrier in self.mission.barriers:
            raise Refusal("exists", f"barrier {op.barrier} exists already")
        events, notes, value, _ = self._op_barrier(AddBarrier(ids=op.skills), client)
        events = [ev.BarrierSet(id=op.barrier, barrier=Barrier(skills=list(op.skills)))]
        return events, notes, {"barrier": op.barrier}, RemoveBarrier(barrier=op.barrier)

    def _op_unbarrier(self, op: RemoveBarrier, client: str):
        b = self.mission.barriers.get(op.barrier)
        if b is None:
            known = ", ".join(self.mission.barriers) or "none"
            raise Refusal("unknown_barrier", f"no barrier '{op.barrier}' (barriers: {known})")
        for sid in b.skills:
            robot, _, s = self.skill(sid)
            if s.status != Status.IDLE and s.status not in FINISHED:
                raise Refusal(
                    "not_idle",
                    f"cannot remove barrier {op.barrier}: {s.display()} is {s.status.value} on {robot}; {how_to_change(s.status)}",
                    robot=robot,
                    skill=sid,
                )
            if sid in self.locked:
                raise Refusal(
                    "locked",
                    f"cannot remove barrier {op.barrier}: {s.display()}: {self.locked[sid]}",
                    robot=robot,
                    skill=sid,
                )
        return (
            [ev.BarrierRemoved(id=op.barrier)],
            [],
            {},
            RestoreBarrier(barrier=op.barrier, skills=list(b.skills)),
        )

    # -- markers -------------------------------------------------------------
    def _marker(self, name: str):
        mk = self.mission.markers.get(name)
        if mk is None:
            known = ", ".join(self.mission.markers) or "none"
            raise Refusal("unknown_marker", f"no marker '{name}' (markers: {known})")
        return mk

    def _op_marker_add(self, op: MarkerAdd, client: str):
        if op.name in self.mission.markers:
            raise Refusal("exists", f"a marker named '{op.name}' exists already")
        return [ev.MarkerSet(name=op.name, marker=op.marker)], [], {}, MarkerDelete(name=op.name)

    def _bound(self, name: str):
        for robot, task in self.mission.tasks.items():
            for s in task:
                for pname, mname in s.bindings.items():
                    if mname == name:
                        yield robot, s, pname

    def _op_marker_move(self, op: MarkerMove, client: str):
        old = self._marker(op.name)
        value = op.value
        if (old.kind == "area") != isinstance(value, list):
            need = "a polygon (a list of positions)" if old.kind == "area" else f"a {old.kind}"
            raise Refusal(
                "bad_marker", f"marker '{op.name}' is a {old.kind} marker: move it to {need}"
            )
        data = old.model_dump()
        if old.kind == "area":
            data["area"] = [p.model_dump() for p in value]
        elif old.kind == "pose":
            data["pose"] = value.model_dump()
        else:
            data["position"] = {k: getattr(value, k) for k in ("x", "y", "z")}
        new = type(old).model_validate(data)
        events: list = [ev.MarkerSet(name=op.name, marker=new)]
        notes: list[str] = []
        stale: list[str] = []
        self.mission.markers[op.name] = new  # to compute the bound values
        try:
            for robot, s, pname in self._bound(op.name):
                if s.status == Status.IDLE:
                    params = self._check_params(robot, s.skill, s.params, s.bindings, skill_id=s.id)
                    if params != s.params:
                        events.append(ev.SkillChanged(id=s.id, changes={"params": params}))
                    if s.id in self.locked:  # left with the old value; its ack will say so
                        stale.append(s.id)
                        notes.append(
                            f"{robot}: {s.display()} is being synchronized with the old value of "
                            f"{op.name} for '{pname}'; unsynchronize it once it is queued to update"
                        )
                elif s.status not in FINISHED:
                    stale.append(s.id)
                    notes.append(
                        f"{robot}: {s.display()} ({s.status.value}) still uses the old value of "
                        f"{op.name} for '{pname}'; unsynchronize it to update"
                    )
        finally:
            self.mission.markers[op.name] = old
        old_value = old.area if old.kind == "area" else getattr(old, old.kind)
        return events, notes, {"stale": stale}, MarkerMove(name=op.name, value=old_value)

    def _named(self, name: str):
        """Skills whose marker-type parameter names marker `name` (not finished)."""
        for robot, task in self.mission.tasks.items():
            rtype = self.mission.robots[robot].type if robot in self.mission.robots else ""
            for s in task:
                spec = self.library.skill_for(rtype, s.skill)
                if spec is None or s.status in FINISHED:
                    continue
                for pname, pspec in spec.params.items():
                    if pspec.type == "marker" and s.params.get(pname) == name:
                        yield robot, s, pname

    def _op_marker_rename(self, op: MarkerRename, client: str):
        mk = self._marker(op.name)
        if op.new_name in self.mission.markers:
            raise Refusal("exists", f"a marker named '{op.new_name}' exists already")
        events: list = [ev.MarkerSet(name=op.new_name, marker=mk), ev.MarkerRemoved(name=op.name)]
        for robot, s, pname in self._named(op.name):
            if s.status != Status.IDLE:
                raise Refusal(
                    "marker_in_use",
                    f"cannot rename marker '{op.name}': {s.display()} on {robot} is {s.status.value} and names it in '{pname}'",
                    robot=robot,
                    skill=s.id,
                )
            events.append(
                ev.SkillChanged(id=s.id, changes={"params": {**s.params, pname: op.new_name}})
            )
        # a binding names where a value came from, not the value: follow the
        # rename on the plan and the queue; the execution log stays as it ran
        for _, s, pname in self._bound(op.name):
            if s.status in FINISHED:
                continue
            events.append(
                ev.SkillChanged(id=s.id, changes={"bindings": {**s.bindings, pname: op.new_name}})
            )
        return events, [], {}, MarkerRename(name=op.new_name, new_name=op.name)

    def _op_marker_delete(self, op: MarkerDelete, client: str):
        marker = self._marker(op.name)
        for robot, s, pname in self._named(op.name):
            raise Refusal(
                "marker_in_use",
                f"cannot delete marker '{op.name}': {s.display()} on {robot} names it in '{pname}'; change that first",
                robot=robot,
                skill=s.id,
            )
        events: list = [ev.MarkerRemoved(name=op.name)]
        unbound: list[tuple[str, str]] = []
        for robot, s, pname in self._bound(op.name):
            if s.status in FINISHED:
                continue  # the execution log keeps the name it ran with
            if s.status != Status.IDLE:
                raise Refusal(
                    "marker_in_use",
                    f"cannot delete marker '{op.name}': {s.display()} on {robot} is {s.status.value} and uses it for '{pname}'",
                    robot=robot,
                    skill=s.id,
                )
            bindings = {k: v for k, v in s.bindings.items() if v != op.name}
            events.append(
                ev.SkillChanged(id=s.id, changes={"bindings": bindings})
            )  # keeps its values
            unbound.append((s.id, pname))
        return events, [], {}, RestoreMarker(name=op.name, marker=marker, bindings=unbound)

    def _op_restore_marker(self, op: RestoreMarker, client: str):
        if op.name in self.mission.markers:
            raise Refusal("exists", f"a marker named '{op.name}' exists already")
        events: list = [ev.MarkerSet(name=op.name, marker=op.marker)]
        self.mission.markers[op.name] = op.marker  # to compute the bound values
        try:
            for sid, pname in op.bindings:
                found = self.mission.find(sid)
                if found is None or found[2].status != Status.IDLE or sid in self.locked:
                    continue  # gone or on a robot since: leave it as it is
                robot, _, s = found
                bindings = {**s.bindings, pname: op.name}
                params = self._check_params(robot, s.skill, s.params, bindings, skill_id=sid)
                events.append(
                    ev.SkillChanged(id=sid, changes={"bindings": bindings, "params": params})
                )
        finally:
            del self.mission.markers[op.name]
        return events, [], {}, MarkerDelete(name=op.name)

    # -- whole missions ----------------------------------------------------------
    def _busy_robots(self) -> list[str]:
        return [
            r
            for r, t in self.mission.tasks.items()
            if any(s.status not in FINISHED and s.status != Status.IDLE for s in t)
        ]

    def _op_load(self, op: LoadMission, client: str):
        if self.pending:
            busy = ", ".join(f"{r} ({what})" for r, what in self.pending.items())
            raise Refusal(
                "robot_busy",
                f"cannot replace the mission while commands are in flight: {busy}; try again when they end",
            )
        busy = self._busy_robots()
        if busy:
            raise Refusal(
                "robots_busy",
                f"cannot replace the mission while {', '.join(busy)} hold synchronized skills; reset them first",
            )
        new = op.mission.copy_deep()
        resolve_shorthands(new, self.library)
        problems = check_mission(new, self.library)
        if problems:
            path, msg = problems[0]
            from backend.core.model import format_path

            raise Refusal("bad_mission", f"the mission is invalid at {format_path(path)}: {msg}")
        new.revision = self.mission.revision
        new.library = (
            self.mission.library
        )  # the server's library stays; the file's path was relative to it
        # everything in the new mission counts as changed now (stale edits of
        # the old mission are refused)
        stamp = self.mission.revision + 1
        for task in new.tasks.values():
            for sk in task:
                sk.rev = stamp
        new.task_revs = dict.fromkeys(new.robots, stamp)
        new.marker_revs = dict.fromkeys(new.markers, stamp)
        new.next_skill = max(new.next_skill, self.mission.next_skill)
        new.next_barrier = max(new.next_barrier, self.mission.next_barrier)
        new.report_seqs = dict(self.mission.report_seqs)
        for robot in new.robots:
            new.tasks.setdefault(robot, [])
        return [ev.MissionReplaced(mission=new)], [], {}, None

    def _op_new(self, op: NewMission, client: str):
        empty = Mission(
            name=op.name,
            library=self.mission.library,
            robots=self.mission.robots,
            tasks={r: [] for r in self.mission.robots},
        )
        return self._op_load(LoadMission(mission=empty), client)

    # -- undo / redo -------------------------------------------------------------
    def _mine(self, client: str, revision: int) -> None:
        own = self.own_revs.setdefault(client, {})
        own[revision] = None  # revisions only grow: the first one is the oldest
        if len(own) > 4 * UNDO_DEPTH:
            del own[next(iter(own))]

    def _push_undo(self, client: str, inverse: Any, what: str, revision: int) -> None:
        stack = self.undo_stack.setdefault(client, [])
        stack.append((inverse, what, revision))
        del stack[:-UNDO_DEPTH]
        self.redo_stack.pop(client, None)  # a new edit starts a new future

    def _revert(self, op: Any, client: str, source: dict, target: dict, verb: str) -> Applied:
        stack = source.get(client) or []
        if not stack:
            raise Refusal(
                f"nothing_to_{verb}",
                f"nothing to {verb} (only your own edits of unsynchronized skills, barriers and markers can be undone)",
            )
        inverse, what, made_at = stack.pop()
        try:
            events, notes, value, back = getattr(self, f"_op_{inverse.op}")(inverse, client)
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
        try:
            applied = self._commit(
                events, notes, {**value, "undone" if verb == "undo" else "redone": what}
            )
        except Exception:  # not applied (the journal refused it): still to do
            stack.append((inverse, what, made_at))
            raise
        self._mine(client, applied.revision)
        if back is not None:
            target.setdefault(client, []).append((back, what, applied.revision))
        return applied

    def _op_undo(self, op: Undo, client: str) -> Applied:
        return self._revert(op, client, self.undo_stack, self.redo_stack, "undo")

    def _op_redo(self, op: Redo, client: str) -> Applied:
        return self._revert(op, client, self.redo_stack, self.undo_stack, "redo")

    # -- two-phase operations: plans ----------------------------------------------
    def _claim(self, robot: str, what: str) -> None:
        if robot in self.pending:
            raise Refusal(
                "robot_busy",
                f"{robot} is busy: {self.pending[robot]} is in progress; try again when it ends",
                robot=robot,
            )

    def plan_sync(self, op: Sync) -> list[SkillInstance]:
        """Skills to send to the robot; they are locked until `release` or the
        robot's `SyncAck`."""
        task = self.task(op.robot)
        self._claim(op.robot, "sync")
        start = self.first_idle(task)
        idle = task[start:]
        if not idle:
            raise Refusal(
                "nothing_to_sync",
                f"{op.robot} has no unsynchronized skill to synchronize",
                robot=op.robot,
            )
        if op.through is None:
            chosen = idle
        else:
            robot, i, s = self.skill(op.through)
            if robot != op.robot:
                raise Refusal(
                    "wrong_robot",
                    f"skill {s.display()} belongs to {robot}, not {op.robot}",
                    robot=op.robot,
                    skill=s.id,
                )
            if s.status != Status.IDLE:
                raise Refusal(
                    "not_idle",
                    f"{s.display()} on {robot} is already {s.status.value}",
                    robot=robot,
                    skill=s.id,
                )
            chosen = task[start : i + 1]
        for s in chosen:
            if s.id in self.locked:
                raise Refusal(
                    "locked",
                    f"{s.display()} on {op.robot}: {self.locked[s.id]}",
                    robot=op.robot,
                    skill=s.id,
                )
        # check against the current library and markers; bound values are
        # taken fresh from their markers as they leave
        fresh = [
            self._check_params(op.robot, s.skill, s.params, s.bindings, skill_id=s.id)
            for s in chosen
        ]
        for s, params in zip(chosen, fresh, strict=True):
            self.locked[s.id] = f"it is being synchronized to {op.robot}"
            self.sent[s.id] = params
        self.pending[op.robot] = "a sync"
        return [
            s.model_copy(update={"params": p}, deep=True)
            for s, p in zip(chosen, fresh, strict=True)
        ]

    def barrier_partners(self, skill_id: str) -> list[tuple[str, str]]:
        """(robot, skill id) of the other members of a skill's barrier."""
        bid = self.mission.barrier_of(skill_id)
        if bid is None:
            return []
        out = []
        for sid in self.mission.barriers[bid].skills:
            if sid != skill_id:
                found = self.mission.find(sid)
                if found:
                    out.append((found[0], sid))
        return out

    def plan_unsync(self, op: Unsync) -> list[str]:
        task = self.task(op.robot)
        self._claim(op.robot, "unsync")
        queued = [s for s in task if s.status == Status.IDLE_SYNCHRONIZED]
        if not queued:
            raise Refusal(
                "nothing_to_unsync",
                f"{op.robot} has no queued (idle_synchronized) skill to unsynchronize",
                robot=op.robot,
            )
        if op.from_id is not None:
            robot, _, s = self.skill(op.from_id)
            if robot != op.robot:
                raise Refusal(
                    "wrong_robot",
                    f"skill {s.display()} belongs to {robot}, not {op.robot}",
                    robot=op.robot,
                    skill=s.id,
                )
            if s.status != Status.IDLE_SYNCHRONIZED:
                raise Refusal(
                    "not_queued",
                    f"{s.display()} on {robot} is {s.status.value}; only queued (idle_synchronized) skills can be unsynchronized",
                    robot=robot,
                    skill=s.id,
                )
            queued = queued[[q.id for q in queued].index(s.id) :]
        self.pending[op.robot] = "an unsync"
        return [s.id for s in queued]

    def plan_control(self, op: Control) -> list[str]:
        """Robots the command goes to; refused when it applies to none."""
        robots = [op.robot] if op.robot is not None else list(self.mission.robots)
        reasons: list[str] = []
        out: list[str] = []
        for r in robots:
            task = self.task(r)
            why = self._control_refusal(op.op, r, task)
            if why is None:
                out.append(r)
            else:
                reasons.append(why)
        if not out:
            if op.robot is not None:
                raise Refusal("not_applicable", reasons[0], robot=op.robot)
            raise Refusal("not_applicable", f"{op.op} applies to no robot: " + "; ".join(reasons))
        for r in out:
            if op.op == "reset":
                self._claim(r, "reset")
        for r in out:
            if op.op == "reset":
                self.pending[r] = "a reset"
        return out

    def _control_refusal(self, action: str, robot: str, task: list[SkillInstance]) -> str | None:
        act = self.active(task)
        queued = self.first_queued(task) is not None
        if action == "run":
            if act is not None and act.status == Status.PAUSED:
                return None
            if act is not None:
                return f"{robot} is already executing {act.display()} ({act.status.value})"
            return None if queued else f"{robot} has nothing to run: synchronize skills first"
        if action == "pause":
            return (
                None
                if act is not None and act.status == Status.RUNNING
                else f"{robot} has no running skill to pause"
            )
        if action == "stop":
            return (
                None
                if act is not None
                else f"{robot} has no running, paused or waiting skill to stop"
            )
        if action == "reset":
            return (
                None if act is not None or queued else f"{robot} has nothing synchronized to reset"
            )
        return f"unknown command {action}"

    def plan_retry(self, op: Retry) -> SkillInstance:
        robot, i, s = self.skill(op.id)
        if s.status != Status.FAILURE:
            raise Refusal(
                "cannot_retry",
                f"{s.display()} on {robot} is {s.status.value}; only a failed skill can be retried",
                robot=robot,
                skill=s.id,
            )
        new_id = f"{s.id.split('.')[0]}.{s.attempt + 1}"
        if self.mission.find(new_id) is not None:
            raise Refusal(
                "cannot_retry",
                f"{s.display()} was already retried as {new_id}",
                robot=robot,
                skill=s.id,
            )
        task = self.task(robot)
        if any(later.status in FINISHED for later in task[i + 1 :]):
            raise Refusal(
                "cannot_retry",
                f"{robot} has executed other skills since {s.display()} failed; add a new skill instead",
                robot=robot,
                skill=s.id,
            )
        act = self.active(task)
        if act is not None:
            raise Refusal(
                "cannot_retry",
                f"cannot retry {s.display()}: {robot} is executing {act.display()}; stop it first",
                robot=robot,
                skill=s.id,
            )
        self._claim(robot, "retry")
        self.pending[robot] = "a retry"
        return SkillInstance(
            id=new_id,
            skill=s.skill,
            label=s.label,
            params=s.params,
            bindings=s.bindings,
            status=Status.IDLE_SYNCHRONIZED,
            attempt=s.attempt + 1,
            policies=s.policies,
        )

    def release(self, robot: str, ids: list[str] = ()) -> None:
        """The command to `robot` ended (answered, refused or timed out)."""
        self.pending.pop(robot, None)
        for sid in ids:
            self.locked.pop(sid, None)
            self.sent.pop(sid, None)

    # -- robot answers ------------------------------------------------------------
    def _op_sync_ack(self, op: SyncAck, client: str):
        task = self.task(op.robot)
        start = self.first_idle(task)
        head = [s.id for s in task[start : start + len(op.ids)]]
        if head != list(op.ids):
            raise Refusal(
                "bad_report",
                f"{op.robot} acknowledged {op.ids}, but the head of its unsynchronized section is {head}",
                robot=op.robot,
            )
        late = [sid for sid in op.ids if sid not in self.sent]
        if late:
            # the sync was given up (and the skill maybe edited since): the
            # robot's copy is not ours; reconciliation sorts it out
            raise Refusal(
                "bad_report",
                f"{op.robot} acknowledged {', '.join(late)}, which is not being synchronized",
                robot=op.robot,
            )
        events = []
        for s in task[start : start + len(op.ids)]:
            changes: dict[str, Any] = {"status": Status.IDLE_SYNCHRONIZED.value}
            if self.sent[s.id] != s.params:
                changes["params"] = self.sent[s.id]  # what the robot holds
            events.append(ev.SkillChanged(id=s.id, changes=changes))
        for sid in op.ids:
            self.locked.pop(sid, None)
            self.sent.pop(sid, None)
        return events, [], {"synchronized": list(op.ids)}, None

    def _op_unsync_done(self, op: UnsyncDone, client: str):
        task = self.task(op.robot)
        queued = [s.id for s in task if s.status == Status.IDLE_SYNCHRONIZED]
        if op.ids and list(op.ids) != queued[-len(op.ids) :]:
            raise Refusal(
                "bad_report",
                f"{op.robot} removed {op.ids}, which is not the end of its queue {queued}",
                robot=op.robot,
            )
        # the removed skills are the end of the queue: turning them idle puts
        # them, in order, at the head of the unsynchronized section
        events = []
        for sid in op.ids:
            _, _, s = self.skill(sid)
            changes: dict[str, Any] = {"status": Status.IDLE.value, "status_info": ""}
            if s.bindings:  # back in the plan: bound values follow their markers again
                try:
                    params = self._check_params(
                        op.robot, s.skill, s.params, s.bindings, skill_id=sid
                    )
                    if params != s.params:
                        changes["params"] = params
                except Refusal:
                    pass  # keeps its values; the operator sees the problem on the next edit
            events.append(ev.SkillChanged(id=sid, changes=changes))
        return events, [], {"unsynchronized": list(op.ids)}, None

    def _op_retry_ack(self, op: RetryAck, client: str):
        robot, i, failed = self.skill(op.failed_id)
        if robot != op.robot or failed.status != Status.FAILURE:
            raise Refusal(
                "bad_report",
                f"{op.robot} acknowledged a retry of {op.failed_id}, which is not a failed skill of it",
                robot=op.robot,
            )
        if self.mission.find(op.skill.id) is not None:
            raise Refusal("bad_report", f"skill {op.skill.id} exists already", robot=op.robot)
        skill = op.skill.model_copy(update={"status": Status.IDLE_SYNCHRONIZED})
        events: list = [ev.SkillAdded(robot=robot, index=i + 1, skill=skill)]
        return events, [], {"id": skill.id}, None

    def _op_reconcile(self, op: Reconcile, client: str):
        task = self.task(op.robot)
        lost = set(op.lost)
        synced = [s for s in task if s.status != Status.IDLE and s.status not in FINISHED]
        # only a tail of the synchronized section can be lost, the log never
        keep = [s for s in synced if s.id not in lost]
        if any(s.id not in lost for s in synced[len(keep) :]) or [
            s.id for s in synced[: len(keep)]
        ] != [s.id for s in keep]:
            raise Refusal(
                "bad_report",
                f"{op.robot} lost {sorted(lost)}, which is not the end of its synchronized section",
                robot=op.robot,
            )
        events = [
            ev.SkillChanged(
                id=s.id,
                changes={
                    "status": Status.IDLE.value,
                    "status_info": f"returned to the plan: {op.robot} no longer had it",
                    "started_at": None,
                },
            )
            for s in synced[len(keep) :]
        ]
        return events, [], {"unsynchronized": [s.id for s in synced[len(keep) :]]}, None

    def _op_report(self, op: Report, client: str):
        m = self.mission
        last = m.report_seqs.get(op.robot, 0)
        if op.seq <= last:
            return Applied(
                m.revision,
                [],
                [],
                {"ignored": f"report {op.seq} of {op.robot} was applied already"},
                duplicate=True,
            )
        robot, i, s = self.skill(op.id)
        if robot != op.robot:
            raise Refusal(
                "bad_report",
                f"{op.robot} reported on {s.display()}, which belongs to {robot}",
                robot=op.robot,
                skill=s.id,
            )
        task = m.tasks[robot]
        new = op.status
        restart = (
            new == Status.RUNNING and s.status == Status.RUNNING and (op.attempt or 0) > s.attempt
        )
        # an active skill may repeat its status with new information
        # ("waiting for lru2 (offline)"); the log and the queue may not
        same = new == s.status and s.status in ACTIVE
        if new not in TRANSITIONS[s.status] and not restart and not same:
            raise Refusal(
                "bad_report",
                f"{robot} reported {s.display()} going {s.status.value} -> {new.value}, which the transition table forbids",
                robot=robot,
                skill=s.id,
            )
        if new in ACTIVE or new in FINISHED:
            act = self.active(task)
            if act is not None and act.id != s.id:
                raise Refusal(
                    "bad_report",
                    f"{robot} reported {s.display()} {new.value} while {act.display()} is {act.status.value}",
                    robot=robot,
                    skill=s.id,
                )
            if s.status == Status.IDLE_SYNCHRONIZED and self.first_queued(task) != i:
                raise Refusal(
                    "bad_report",
                    f"{robot} started {s.display()} before the skills queued ahead of it",
                    robot=robot,
                    skill=s.id,
                )
        if op.attempt is not None and op.attempt < s.attempt:
            raise Refusal(
                "bad_report",
                f"{robot} reported attempt {op.attempt} of {s.display()}, which is at attempt {s.attempt}",
                robot=robot,
                skill=s.id,
            )
        changes: dict[str, Any] = {}
        if new != s.status:
            changes["status"] = new.value
        if op.info != s.status_info:
            changes["status_info"] = op.info
        if op.attempt is not None and op.attempt != s.attempt:
            changes["attempt"] = op.attempt
        at = op.at.isoformat() if op.at else None
        if new == Status.RUNNING and s.started_at is None and at:
            changes["started_at"] = at
        if new in FINISHED and at:
            changes["finished_at"] = at
        if new == Status.IDLE_SYNCHRONIZED:
            changes["started_at"] = None  # stopped: the next run starts it from the beginning
        events: list = [ev.ReportSeq(robot=robot, seq=op.seq)]
        if changes:
            events.append(ev.SkillChanged(id=s.id, changes=changes))
        return events, [], {}, None
