"""Editing the unsynchronized section: add, delete, move and edit skills, an
editable retry of a failed skill, and the internal operations that undo
those (restore skills, set a skill)."""

from __future__ import annotations

from typing import Any

from backend.core import events as ev
from backend.core.model import FINISHED, Barrier, Policies, SkillInstance, Status
from backend.core.ops import (
    AddSkill,
    DeleteSkills,
    EditSkill,
    MoveSkill,
    RestoreItem,
    RestoreSkills,
    RetryEdit,
    SetSkill,
)
from backend.core.rules import contingency
from backend.core.rules.base import Change, Refusal, Rule, Rules, unchanged
from backend.core.rules.execution import check_failed_once


def add(rules: Rules, op: AddSkill) -> Change:
    task = rules.task(op.robot)
    params = rules.check_params(op.robot, op.skill, op.params, op.bindings)
    contingency.check(rules, op.robot, op.policies, None)
    start = rules.first_idle(task)
    n_idle = len(task) - start
    at = n_idle if op.at is None else op.at
    if not 0 <= at <= n_idle:
        raise Refusal(
            "bad_index",
            f"position {at} is outside {op.robot}'s unsynchronized section (0..{n_idle})",
            robot=op.robot,
        )
    rules.outside_locked(op.robot, task, start + at)
    n = rules.mission.next_skill
    while rules.mission.find(f"{op.robot}-{n}") is not None:  # ids from files may use any numbers
        n += 1
    sid = f"{op.robot}-{n}"
    skill = SkillInstance(
        id=sid,
        skill=op.skill,
        label=op.label,
        params=params,
        bindings=dict(op.bindings),
        policies=op.policies or Policies(),
    )
    events: list[ev.Event] = [ev.SkillAdded(robot=op.robot, index=start + at, skill=skill)]
    return Change(events, [], {"id": sid}, DeleteSkills(ids=[sid]))


def retry_edit(rules: Rules, op: RetryEdit) -> Change:
    """The failed skill's next attempt, idle, first in its robot's plan: the
    operator edits it, then synchronizes it (the failed one stays in the log)."""
    robot, _, s = rules.skill(op.id)
    check_failed_once(rules, robot, s)
    new_id = s.retry_id()
    task = rules.task(robot)
    start = rules.first_idle(task)
    rules.outside_locked(robot, task, start)
    # bound parameters take their markers' values now (a marker may have moved or gone)
    bindings = {k: v for k, v in s.bindings.items() if v in rules.mission.markers}
    params = rules.check_params(robot, s.skill, s.params, bindings, skill_id=new_id)
    skill = s.next_attempt().model_copy(update={"params": params, "bindings": bindings})
    events: list[ev.Event] = [ev.SkillAdded(robot=robot, index=start, skill=skill)]
    return Change(events, [], {"id": new_id}, DeleteSkills(ids=[new_id]))


def delete(rules: Rules, op: DeleteSkills) -> Change:
    items = _removed(rules, op.ids, "delete")
    gone = {it.skill.id for it in items}
    events, barriers_before = _barriers_without(rules, gone, "delete")
    # remove from the highest index down so the recorded indices stay valid to restore
    for it in sorted(items, key=lambda it: (it.robot, -it.index)):
        events.insert(0, ev.SkillRemoved(robot=it.robot, id=it.skill.id))
    restore = RestoreSkills(
        items=sorted(items, key=lambda it: (it.robot, it.index)), barriers=barriers_before
    )
    return Change(events, [], {}, restore)


def _removed(rules: Rules, ids: list[str], doing: str) -> list[RestoreItem]:
    """Where each skill to remove is, refused unless all may change."""
    items: list[RestoreItem] = []
    for sid in dict.fromkeys(ids):
        robot, i, s = rules.skill(sid)
        rules.editable(robot, s, doing)
        items.append(RestoreItem(robot=robot, index=i, skill=s))
    return items


def _barriers_without(
    rules: Rules, gone: set[str], doing: str
) -> tuple[list[ev.Event], dict[str, Barrier]]:
    """The barriers that lose members (kept if they still join two robots)
    and, to restore them, what they were."""
    events: list[ev.Event] = []
    barriers_before: dict[str, Barrier] = {}
    for bid, b in rules.mission.barriers.items():
        if not gone & set(b.skills):
            continue
        rest = [sid for sid in b.skills if sid not in gone]
        robots_left = {_unsynchronized_partner(rules, bid, sid, gone, doing) for sid in rest}
        barriers_before[bid] = b
        if len(robots_left) >= 2:
            events.append(ev.BarrierSet(id=bid, barrier=b.model_copy(update={"skills": rest})))
        else:
            events.append(ev.BarrierRemoved(id=bid))
    return events, barriers_before


def _unsynchronized_partner(rules: Rules, bid: str, sid: str, gone: set[str], doing: str) -> str:
    """The robot of a barrier partner left behind; refused if it is on its robot."""
    robot, _, partner = rules.skill(sid)
    if partner.status != Status.IDLE and partner.status not in FINISHED:
        b = rules.mission.barriers[bid]
        raise Refusal(
            "barrier_partner_synchronized",
            f"cannot {doing} {', '.join(sorted(gone & set(b.skills)))}: barrier {bid} ties it to "
            f"{partner.display()}, already on {robot}; unsynchronize {partner.id} first",
            robot=robot,
            skill=partner.id,
        )
    return robot


def restore_skills(rules: Rules, op: RestoreSkills) -> Change:
    events = _restored_skills(rules, op.items)
    events += _restored_barriers(rules, op)
    return Change(events, [], {}, DeleteSkills(ids=[it.skill.id for it in op.items]))


def _restored_skills(rules: Rules, items: list[RestoreItem]) -> list[ev.Event]:
    events: list[ev.Event] = []
    sizes: dict[str, int] = {}
    for it in sorted(items, key=lambda it: (it.robot, it.index)):
        if rules.mission.find(it.skill.id) is not None:
            raise Refusal("exists", f"skill {it.skill.id} exists already", skill=it.skill.id)
        task = rules.task(it.robot)
        sizes.setdefault(it.robot, len(task))
        # ascending indices: each insert lands where the skill was, unless
        # the synchronized section has grown since
        idx = min(max(it.index, rules.first_idle(task)), sizes[it.robot])
        rules.outside_locked(it.robot, task, min(idx, len(task)))
        sizes[it.robot] += 1
        events.append(ev.SkillAdded(robot=it.robot, index=idx, skill=_as_restored(rules, it)))
    return events


def _as_restored(rules: Rules, it: RestoreItem) -> SkillInstance:
    bindings = {k: v for k, v in it.skill.bindings.items() if v in rules.mission.markers}
    try:  # markers may have moved since: take their current values
        params = rules.check_params(
            it.robot, it.skill.skill, it.skill.params, bindings, skill_id=it.skill.id
        )
    except Refusal:
        params, bindings = it.skill.params, {}
    return it.skill.model_copy(
        update={"status": Status.IDLE, "params": params, "bindings": bindings}
    )


def _restored_barriers(rules: Rules, op: RestoreSkills) -> list[ev.Event]:
    events: list[ev.Event] = []
    restored = {it.skill.id for it in op.items}
    for bid, b in op.barriers.items():
        for sid in b.skills:
            if sid not in restored:
                _check_partner_unchanged(rules, bid, sid)
        events.append(ev.BarrierSet(id=bid, barrier=b))
    return events


def _check_partner_unchanged(rules: Rules, bid: str, sid: str) -> None:
    """Refused unless barrier `bid`'s partner `sid` is still idle and in no
    other barrier."""
    robot, _, partner = rules.skill(sid)
    other = rules.mission.barrier_of(sid)
    if partner.status != Status.IDLE or other not in (None, bid):
        raise Refusal(
            "barrier_invalid",
            f"cannot restore barrier {bid}: its partner {partner.display()} on {robot} "
            "has changed since",
            robot=robot,
            skill=sid,
        )


def move(rules: Rules, op: MoveSkill) -> Change:
    robot, i, s = rules.skill(op.id)
    rules.editable(robot, s, "move")
    task = rules.task(robot)
    start = rules.first_idle(task)
    n_idle = len(task) - start
    if not 0 <= op.index < n_idle:
        raise Refusal(
            "bad_index",
            f"position {op.index} is outside {robot}'s unsynchronized section (0..{n_idle - 1})",
            robot=robot,
            skill=op.id,
        )
    if start + op.index == i:
        return unchanged()
    rules.outside_locked(robot, task, min(start + op.index, i))
    return Change(
        [ev.SkillMoved(robot=robot, id=op.id, index=start + op.index)],
        [],
        {},
        MoveSkill(id=op.id, index=i - start),
    )


def edit(rules: Rules, op: EditSkill) -> Change:
    robot, _, s = rules.skill(op.id)
    rules.editable(robot, s, "edit")
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
    return set_skill(rules, new)


def set_skill(rules: Rules, op: SetSkill) -> Change:
    robot, _, s = rules.skill(op.id)
    rules.editable(robot, s, "edit")
    params = _set_params(rules, robot, s, op)
    if op.policies != s.policies:
        contingency.check(rules, robot, op.policies, s.id)
    edit = _edited(s, op, params)
    if edit == ev.SkillEdited(id=s.id):
        return unchanged()
    old = SetSkill(
        id=s.id, label=s.label, params=s.params, bindings=s.bindings, policies=s.policies
    )
    return Change([edit], [], {}, old)


def _set_params(rules: Rules, robot: str, s: SkillInstance, op: SetSkill) -> dict[str, Any]:
    """The parameters a SetSkill gives the skill, checked."""
    if not op.bindings and not s.bindings and op.params == s.params:
        # checked when they were set (e.g. only the label changes); bound
        # ones are re-resolved below, as a marker may have moved since
        return s.params
    return rules.check_params(robot, s.skill, op.params, op.bindings, skill_id=s.id)


def _edited(s: SkillInstance, op: SetSkill, params: dict[str, Any]) -> ev.SkillEdited:
    """The event of a SetSkill: the fields it changes, the others None."""
    return ev.SkillEdited(
        id=s.id,
        label=op.label if op.label != s.label else None,
        params=params if params != s.params else None,
        bindings=op.bindings if op.bindings != s.bindings else None,
        policies=op.policies if op.policies != s.policies else None,
    )


RULES: dict[type[Any], Rule] = {
    AddSkill: add,
    RetryEdit: retry_edit,
    DeleteSkills: delete,
    RestoreSkills: restore_skills,
    MoveSkill: move,
    EditSkill: edit,
    SetSkill: set_skill,
}
