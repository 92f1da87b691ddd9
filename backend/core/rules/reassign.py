"""Reassignment: idle skills given to another robot whose type and manifest
offer them (issue 30), keeping parameters, marker bindings and order.

Each skill that cannot move says why; the others move. A barrier that
would tie two skills of one robot is dissolved (saying so); the others
follow their skills (a barrier names skills, not robots). An `after` link
(`policies.after`) names a skill, not a robot, so it follows too: the
robot asked is the awaited skill's, wherever it is now; one that would
make a robot wait for itself is dissolved, saying which skill its plan
runs first. A skill awaited by one already on a robot stays (the waiter
asks its robot by name). A barrier partner whose robot parameter
(`talks_to`) named the robot a skill left names the new one. Undone by
`ReturnSkills`: each skill back where it was, with its barriers, `after`
links and partners' parameters.
"""

from __future__ import annotations

from typing import Any

from backend.core import events as ev
from backend.core.model import ACTIVE, FINISHED, Barrier, Mission, SkillInstance, Status
from backend.core.ops import Reassign, RestoreItem, ReturnSkills
from backend.core.rules.base import Change, Refusal, Rule, Rules, check_in_service
from backend.core.rules.uplink import incompatible

__all__ = ["chosen", "held", "incompatible", "reassign", "return_skills", "why_not"]


def chosen(rules: Rules, op: Reassign) -> list[str]:
    """The ids to move, in the order of their lists: those named, then the
    unsynchronized plan of `from_robot`."""
    ids = list(op.ids) + _plan_of(rules, op.from_robot)
    if not ids:
        source = f"{op.from_robot} has no unsynchronized skill" if op.from_robot else "no skill"
        raise Refusal("nothing_to_reassign", f"nothing to give to {op.to}: {source}", robot=op.to)
    order = {r: n for n, r in enumerate(rules.mission.tasks)}
    places = {sid: rules.skill(sid)[:2] for sid in dict.fromkeys(ids)}  # refused if unknown
    return sorted(places, key=lambda sid: (order[places[sid][0]], places[sid][1]))


def _plan_of(rules: Rules, robot: str | None) -> list[str]:
    if robot is None:
        return []
    return [s.id for s in rules.task(robot) if s.status == Status.IDLE]


Waiters = dict[str, list[tuple[str, SkillInstance]]]  # awaited id -> (robot, waiter)


def waiters(m: Mission) -> Waiters:
    """Each skill that some unfinished skill waits for (`after`), and those waiters."""
    out: Waiters = {}
    for robot, task in m.tasks.items():
        for s in task:
            if s.policies.after is not None and s.status not in FINISHED:
                out.setdefault(s.policies.after, []).append((robot, s))
    return out


def why_not(rules: Rules, s: SkillInstance, robot: str, to: str, waiting: Waiters) -> str | None:
    """Why skill `s` of `robot` cannot go to `to` (None: it can); `waiting`: the
    mission's `waiters`."""
    if robot == to:
        return f"it is {to}'s already"
    if s.status != Status.IDLE:
        return f"it is {s.status.value}: only unsynchronized (idle) skills move"
    held = _barrier_held(rules, s, to) or _after_held(s, robot, waiting)
    return rules.locked.get(s.id) or _unable(rules, s, to) or held


def _after_held(s: SkillInstance, robot: str, waiting: Waiters) -> str | None:
    """A waiter on its robot already asks this skill's robot, by name: it cannot change."""
    for other, w in waiting.get(s.id, []):
        if w.status != Status.IDLE:
            return (
                f"{w.display()} ({w.status.value} on {other}) waits for it, asking {robot} "
                f"robot to robot; {_free(other, w)}"
            )
    return None


def _free(robot: str, s: SkillInstance) -> str:
    """What frees `s` of `robot` (queued or under way) to change with the skill that moves."""
    if s.status in ACTIVE:  # a queued skill only can be unsynchronized
        return f"stop {robot} ({s.id} goes back to its queue), then unsynchronize {s.id}"
    return f"unsynchronize {s.id} first"


def held(rules: Rules, robot: str) -> list[str]:
    """Why skills of `robot`'s plan can go to no robot yet: a partner under way
    elsewhere waits for `robot` by name (said when it is retired)."""
    waiting = waiters(rules.mission)
    whys = ((s.id, _held(rules, s, robot, waiting)) for s in rules.task(robot))
    return [f"{sid} cannot be given away yet: {why}" for sid, why in whys if why]


def _held(rules: Rules, s: SkillInstance, robot: str, waiting: Waiters) -> str | None:
    if s.status not in (Status.IDLE, Status.IDLE_SYNCHRONIZED):
        return None  # the log, or the interrupted skill (its next attempt is in the plan)
    return _barrier_held(rules, s, robot) or _after_held(s, robot, waiting)


def _unable(rules: Rules, s: SkillInstance, to: str) -> str | None:
    """Why `to` cannot run `s`: its type, its manifest, the parameters."""
    rtype = rules.robot_type(to)
    spec = rules.library.skill_for(rtype, s.skill)
    if spec is None:
        return f"{to} ({rtype}) has no skill '{s.skill}'"
    if spec.talks_to is not None and s.params.get(spec.talks_to) == to:
        return f"its {spec.talks_to} is {to}: a robot is not its own partner"
    return _not_offered(rules, s.skill, spec.version, to) or _bad_params(rules, s, to)


def _not_offered(rules: Rules, skill: str, version: str, to: str) -> str | None:
    """Why `to`'s manifest refuses the skill (None: it offers it, or is not known)."""
    offered = rules.offers.offered(to) if rules.offers is not None else None
    why = incompatible(offered, skill, version) if offered is not None else None
    return f"{to} {why}" if why is not None else None


def _bad_params(rules: Rules, s: SkillInstance, to: str) -> str | None:
    try:
        rules.check_params(to, s.skill, s.params, s.bindings, skill_id=s.id)
    except Refusal as r:
        return r.message
    return None


def _barrier_held(rules: Rules, s: SkillInstance, to: str) -> str | None:
    """A partner already on its robot waits for this skill's robot: it cannot change."""
    bid = rules.mission.barrier_of(s.id)
    if bid is None:
        return None
    for sid in rules.mission.barriers[bid].skills:
        robot, _, partner = rules.skill(sid)
        if partner.status != Status.IDLE and partner.status not in FINISHED and robot != to:
            return (
                f"barrier {bid} ties it to {partner.display()}, {partner.status.value} on "
                f"{robot} (which waits for this skill's robot by name); {_free(robot, partner)}"
            )
    return None


def reassign(rules: Rules, op: Reassign) -> Change:
    rules.robot_type(op.to)
    check_in_service(rules, op.to)
    waiting = waiters(rules.mission)
    items, refused = _split(rules, chosen(rules, op), op.to, waiting)
    moved = {it.skill.id for it in items}
    barrier_events, before, barrier_notes = _barriers(rules, moved, op.to)
    partner_events, partners, partner_notes = _partners(rules, items, op.to, set(before))
    after_events, afters, after_notes = _afters(rules, moved_ids(items), op.to, waiting)
    events: list[ev.Event] = [
        ev.SkillRemoved(robot=it.robot, id=it.skill.id)
        for it in sorted(items, key=lambda it: (it.robot, -it.index))
    ]
    end = len(rules.task(op.to))
    events += [
        ev.SkillAdded(robot=op.to, index=end + n, skill=_given(it)) for n, it in enumerate(items)
    ]
    notes = [f"{len(items)} skill(s) given to {op.to}: {', '.join(moved_ids(items))}"]
    notes += [f"{sid} stays: {why}" for sid, why in refused.items()] + barrier_notes
    notes += _order_notes(rules, items, refused, op.to)
    notes += partner_notes + after_notes
    value = {
        "to": op.to,
        "moved": moved_ids(items),
        "refused": refused,
        "dissolved": list(before),
        "afters_dissolved": afters,
        "partners_renamed": partners,
    }
    undo = ReturnSkills(items=items, to=op.to, barriers=before, afters=afters, partners=partners)
    events += barrier_events + partner_events + after_events
    return Change(events, notes, value, undo)


def _given(it: RestoreItem) -> SkillInstance:
    """The skill as its new robot holds it: what it said of its old robot
    ('taken back on the ground: lru1 was retired…') is not true of the new one."""
    if not it.skill.status_info:
        return it.skill
    return it.skill.model_copy(update={"status_info": f"given by {it.robot}"})


def _split(
    rules: Rules, ids: list[str], to: str, waiting: Waiters
) -> tuple[list[RestoreItem], dict[str, str]]:
    """The skills that can go to `to` (where they are), and why the others cannot;
    refused when none can."""
    items: list[RestoreItem] = []
    refused: dict[str, str] = {}
    for sid in ids:
        robot, i, s = rules.skill(sid)
        why = why_not(rules, s, robot, to, waiting)
        if why is None:
            items.append(RestoreItem(robot=robot, index=i, skill=s))
        else:
            refused[sid] = why
    if not items:
        said = "; ".join(f"{sid}: {why}" for sid, why in refused.items())
        raise Refusal("cannot_reassign", f"nothing can go to {to}: {said}", robot=to)
    return items, refused


def _order_notes(
    rules: Rules, items: list[RestoreItem], refused: dict[str, str], to: str
) -> list[str]:
    """A skill that stays, ahead of moved ones of its robot, goes last on `to` when
    it is given later: the plan's order is lost unless the operator restores it
    (seen in the demo: an identification after the science image it prepared)."""
    notes = []
    for sid in refused:
        robot, later = rules.skill(sid)[0], _moved_after(rules, items, sid)
        if later is not None:
            notes.append(
                f"{sid} came before {later} on {robot}: given later, it goes last on {to}; "
                f"move it before {later} there, or undo and give them once {sid} can move"
            )
    return notes


def _moved_after(rules: Rules, items: list[RestoreItem], sid: str) -> str | None:
    """The first moved skill that came after `sid` on its robot (None: none, or
    `sid` is finished: the log has no order to keep)."""
    robot, i, s = rules.skill(sid)
    if s.status in FINISHED:
        return None
    return next((it.skill.id for it in items if it.robot == robot and it.index > i), None)


def moved_ids(items: list[RestoreItem]) -> list[str]:
    return [it.skill.id for it in items]


def _barriers(
    rules: Rules, moved: set[str], to: str
) -> tuple[list[ev.Event], dict[str, Barrier], list[str]]:
    """Barriers whose members would share a robot are dissolved (and kept to
    restore); the others follow their skills (said in a note)."""
    events: list[ev.Event] = []
    before: dict[str, Barrier] = {}
    notes: list[str] = []
    for bid, b in rules.mission.barriers.items():
        if not moved & set(b.skills):
            continue
        robots = [to if sid in moved else rules.skill(sid)[0] for sid in b.skills]
        if len(set(robots)) == len(robots):
            notes.append(f"barrier {bid} now ties {', '.join(b.skills)} on {', '.join(robots)}")
            continue
        before[bid] = b
        events.append(ev.BarrierRemoved(id=bid))
        notes.append(
            f"barrier {bid} dissolved: {', '.join(b.skills)} would all be on {to}, and a "
            "robot never waits for itself"
        )
    return events, before, notes


def _partners(
    rules: Rules, items: list[RestoreItem], to: str, dissolved: set[str]
) -> tuple[list[ev.Event], dict[str, str], list[str]]:
    """A barrier that follows its skill to `to` keeps its partners together
    only if they work with `to` now: a partner skill whose robot parameter
    (`talks_to`, e.g. identify_stone's partner) names the robot a member left
    names `to` instead (and the robot it named is kept to restore)."""
    came_from = {it.skill.id: it.robot for it in items}
    kept = set(rules.mission.barriers) - dissolved
    edits = [edit for bid in sorted(kept) for edit in _partner_edits(rules, bid, came_from, to)]
    return _said_partners(edits, to)


def _said_partners(
    edits: list[tuple[ev.SkillEdited, str]], to: str
) -> tuple[list[ev.Event], dict[str, str], list[str]]:
    notes = [f"{e.id} works with {to} now (its partner was {was})" for e, was in edits]
    return [e for e, _ in edits], {e.id: was for e, was in edits}, notes


def _partner_edits(
    rules: Rules, bid: str, came_from: dict[str, str], to: str
) -> list[tuple[ev.SkillEdited, str]]:
    """The renames in barrier `bid`: its members that stay, naming a robot one left."""
    members = rules.mission.barriers[bid].skills
    left = {came_from.get(sid) for sid in members} - {None}
    stay = sorted(set(members) - came_from.keys())
    return [f for f in (_renamed(rules, sid, left, to) for sid in stay) if f is not None]


def _renamed(
    rules: Rules, sid: str, left: set[str | None], to: str
) -> tuple[ev.SkillEdited, str] | None:
    """The edit that has idle skill `sid` name `to` where it named one of `left`,
    and the robot it named (None: it names none of them)."""
    _, _, s = rules.skill(sid)
    param = _talks_to(rules, s.skill)
    if param is None or s.status != Status.IDLE or s.params.get(param) not in left:
        return None
    return ev.SkillEdited(id=sid, params={**s.params, param: to}), str(s.params[param])


def _talks_to(rules: Rules, skill: str) -> str | None:
    """The skill's parameter naming a robot it works with (the library's `talks_to`)."""
    spec = rules.library.skills.get(skill)
    return spec.talks_to if spec is not None else None


def _afters(
    rules: Rules, moved: list[str], to: str, waiting: Waiters
) -> tuple[list[ev.Event], dict[str, str], list[str]]:
    """`after` links of or to the moved skills: each follows its skill (said),
    or is dissolved (and kept to restore) where a robot would wait for itself."""
    order = [s.id for s in rules.task(to)] + moved  # `to`'s plan once they moved
    gone = set(moved)
    events: list[ev.Event] = []
    afters: dict[str, str] = {}
    notes: list[str] = []
    for w, a in _links(moved, waiting):
        here, there = _where(rules, w.id, to, gone), _where(rules, a, to, gone)
        if here != there:  # (an awaited skill that is gone: its check says so)
            notes.append(f"{w.id} (on {here}) still starts after {a}, now on {there or '?'}")
            continue
        afters[w.id] = a
        policies = w.policies.model_copy(update={"after": None})
        events.append(ev.SkillEdited(id=w.id, policies=policies))
        notes.append(_dissolved(w.id, a, to, order))
    return events, afters, notes


def _links(moved: list[str], waiting: Waiters) -> list[tuple[SkillInstance, str]]:
    """(waiter, awaited id) of every link with a moved skill at one end or both."""
    gone = set(moved)
    return [(w, a) for a, ws in waiting.items() for _, w in ws if a in gone or w.id in gone]


def _where(rules: Rules, sid: str, to: str, gone: set[str]) -> str | None:
    """The robot skill `sid` is on once the skills in `gone` moved to `to`."""
    found = rules.mission.find(sid)
    return to if sid in gone else (found[0] if found is not None else None)


def _dissolved(waiter: str, awaited: str, to: str, order: list[str]) -> str:
    said = (
        f"{waiter} no longer starts after {awaited}: both are on {to} now, and a robot never "
        "waits for itself"
    )
    if order.index(awaited) < order.index(waiter):
        return f"{said}; its plan runs {awaited} first, as before"
    return f"{said}; its plan runs {waiter} first: move {awaited} above it to keep the order"


def return_skills(rules: Rules, op: ReturnSkills) -> Change:
    """Each skill back where it was (the undo of a reassignment)."""
    events: list[ev.Event] = []
    for it in op.items:
        robot, _, s = rules.skill(it.skill.id)
        rules.editable(robot, s, "give back")
        events.append(ev.SkillRemoved(robot=robot, id=s.id))
    sizes: dict[str, int] = {}
    for it in sorted(op.items, key=lambda it: (it.robot, it.index)):
        task = rules.task(it.robot)
        sizes.setdefault(it.robot, len(task))
        idx = min(max(it.index, rules.first_idle(task)), sizes[it.robot])
        sizes[it.robot] += 1
        _, _, now = rules.skill(it.skill.id)  # as it is now (it may have been edited)
        back = now.model_copy(update={"status_info": it.skill.status_info})  # its own news
        events.append(ev.SkillAdded(robot=it.robot, index=idx, skill=back))
    events += [ev.BarrierSet(id=bid, barrier=b) for bid, b in op.barriers.items()]
    events += _relinked(rules, op.afters) + _partners_back(rules, op.partners, op.to)
    ids = [it.skill.id for it in op.items]
    return Change(events, [], {"returned": ids}, Reassign(ids=ids, to=op.to))


def _relinked(rules: Rules, afters: dict[str, str]) -> list[ev.Event]:
    """The `after` links a reassignment dissolved, set again (on skills still unfinished)."""
    events: list[ev.Event] = []
    for sid, awaited in afters.items():
        found = rules.mission.find(sid)
        if found is None or found[2].status in FINISHED:
            continue
        policies = found[2].policies.model_copy(update={"after": awaited})
        events.append(ev.SkillEdited(id=sid, policies=policies))
    return events


def _partners_back(rules: Rules, partners: dict[str, str], to: str) -> list[ev.Event]:
    """The partner parameters a reassignment renamed, naming the robot they
    named before (on skills still idle that name `to`: a later edit stays)."""
    events: list[ev.Event] = []
    for sid, was in partners.items():
        found = rules.mission.find(sid)
        back = _renamed(rules, sid, {to}, was) if found is not None else None
        if back is not None:
            events.append(back[0])
    return events


RULES: dict[type[Any], Rule] = {Reassign: reassign, ReturnSkills: return_skills}
