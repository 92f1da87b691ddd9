"""Barriers: skills of different robots that start together. Put idle skills
in a barrier, remove one (and restore it, for undo)."""

from __future__ import annotations

from typing import Any

from backend.core import events as ev
from backend.core.model import FINISHED, Barrier, BarrierTimeout, Status, how_to_change
from backend.core.ops import AddBarrier, EditBarrier, RemoveBarrier, RestoreBarrier
from backend.core.rules.base import Change, Refusal, Rule, Rules


def add_barrier(rules: Rules, op: AddBarrier) -> Change:
    m = rules.mission
    robots: dict[str, str] = {}  # robot -> its skill in the barrier
    for sid in op.ids:
        _check_joinable(rules, sid, robots)
    if len(robots) < 2:
        raise Refusal("barrier_invalid", "a barrier needs skills of at least two robots")
    n = m.next_barrier
    while f"b{n}" in m.barriers:
        n += 1
    bid = f"b{n}"
    return Change(
        [ev.BarrierSet(id=bid, barrier=Barrier(skills=list(op.ids), **_waiting(op)))],
        [],
        {"barrier": bid},
        RemoveBarrier(barrier=bid),
    )


def _check_joinable(rules: Rules, sid: str, robots: dict[str, str]) -> None:
    """Refused unless skill `sid` may join the barrier whose skills so far are
    `robots` (robot -> skill); then it joins."""
    robot, _, s = rules.skill(sid)
    if s.status != Status.IDLE:
        raise Refusal(
            "not_idle",
            f"cannot put {s.display()} on {robot} in a barrier: it is {s.status.value}; "
            "barriers join idle skills",
            robot=robot,
            skill=sid,
        )
    if sid in rules.locked:
        raise Refusal(
            "locked",
            f"cannot put {s.display()} in a barrier: {rules.locked[sid]}",
            robot=robot,
            skill=sid,
        )
    if robot in robots:
        raise Refusal(
            "barrier_invalid",
            f"skills {robots[robot]} and {sid} both belong to {robot}; "
            "a barrier takes one skill per robot",
            robot=robot,
            skill=sid,
        )
    robots[robot] = sid
    other = rules.mission.barrier_of(sid)
    if other is not None:
        raise Refusal(
            "barrier_invalid",
            f"{s.display()} on {robot} is already in barrier {other}",
            robot=robot,
            skill=sid,
        )


def restore_barrier(rules: Rules, op: RestoreBarrier) -> Change:
    if op.barrier in rules.mission.barriers:
        raise Refusal("exists", f"barrier {op.barrier} exists already")
    # the same checks as a new barrier, under its old name
    notes = add_barrier(rules, AddBarrier(ids=op.skills)).notes
    barrier = Barrier(skills=list(op.skills), **_waiting(op))
    events: list[ev.Event] = [ev.BarrierSet(id=op.barrier, barrier=barrier)]
    return Change(events, notes, {"barrier": op.barrier}, RemoveBarrier(barrier=op.barrier))


def _existing(rules: Rules, bid: str) -> Barrier:
    b = rules.mission.barriers.get(bid)
    if b is None:
        known = ", ".join(rules.mission.barriers) or "none"
        raise Refusal("unknown_barrier", f"no barrier '{bid}' (barriers: {known})")
    return b


def edit_barrier(rules: Rules, op: EditBarrier) -> Change:
    """A barrier's timeout and what follows it, while all its skills are idle."""
    b = _existing(rules, op.barrier)
    for sid in b.skills:
        robot, _, s = rules.skill(sid)
        if s.status != Status.IDLE:
            raise Refusal(
                "not_idle",
                f"cannot change barrier {op.barrier}'s timeout: {s.display()} is "
                f"{s.status.value} on {robot}, which holds the barrier as it was synchronized; "
                f"{how_to_change(s.status)}",
                robot=robot,
                skill=sid,
            )
        _unlocked(rules, op.barrier, robot, sid, s.display())
    new = b.model_copy(update=_waiting(op))
    return Change(
        [ev.BarrierSet(id=op.barrier, barrier=new)],
        [],
        {"barrier": op.barrier},
        EditBarrier(barrier=op.barrier, **_waiting(b)),
    )


def _unlocked(rules: Rules, bid: str, robot: str, sid: str, shown: str) -> None:
    if sid in rules.locked:
        raise Refusal(
            "locked",
            f"cannot change barrier {bid}: {shown}: {rules.locked[sid]}",
            robot=robot,
            skill=sid,
        )


def remove_barrier(rules: Rules, op: RemoveBarrier) -> Change:
    b = _existing(rules, op.barrier)
    for sid in b.skills:
        robot, _, s = rules.skill(sid)
        if s.status != Status.IDLE and s.status not in FINISHED:
            raise Refusal(
                "not_idle",
                f"cannot remove barrier {op.barrier}: {s.display()} is {s.status.value} "
                f"on {robot}; {how_to_change(s.status)}",
                robot=robot,
                skill=sid,
            )
        if sid in rules.locked:
            raise Refusal(
                "locked",
                f"cannot remove barrier {op.barrier}: {s.display()}: {rules.locked[sid]}",
                robot=robot,
                skill=sid,
            )
    return Change(
        [ev.BarrierRemoved(id=op.barrier)],
        [],
        {},
        RestoreBarrier(barrier=op.barrier, skills=list(b.skills), **_waiting(b)),
    )


def _waiting(b: BarrierTimeout) -> dict[str, Any]:
    """A barrier's timeout and what follows it, to carry over."""
    return {"timeout": b.timeout, "on_timeout": b.on_timeout}


def barrier_partners(rules: Rules, skill_id: str) -> list[tuple[str, str]]:
    """(robot, skill id) of the other members of a skill's barrier."""
    bid = rules.mission.barrier_of(skill_id)
    if bid is None:
        return []
    out = []
    for sid in rules.mission.barriers[bid].skills:
        if sid != skill_id:
            found = rules.mission.find(sid)
            if found:
                out.append((found[0], sid))
    return out


RULES: dict[type[Any], Rule] = {
    AddBarrier: add_barrier,
    RestoreBarrier: restore_barrier,
    RemoveBarrier: remove_barrier,
    EditBarrier: edit_barrier,
}
