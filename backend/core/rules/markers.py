"""Markers: named poses, positions and areas that parameters are bound to
(their value follows the marker) or that marker parameters name. Add, move,
rename and delete a marker (and restore it, for undo)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from backend.core import events as ev
from backend.core.library import SkillSpec
from backend.core.model import (
    FINISHED,
    AreaMarker,
    Marker,
    Pose,
    PoseMarker,
    Position,
    SkillInstance,
    Status,
)
from backend.core.ops import MarkerAdd, MarkerDelete, MarkerMove, MarkerRename, RestoreMarker
from backend.core.rules.base import Change, Refusal, Rule, Rules

MarkerValue = Pose | Position | list[Position]


def marker(rules: Rules, name: str) -> Marker:
    mk = rules.mission.markers.get(name)
    if mk is None:
        known = ", ".join(rules.mission.markers) or "none"
        raise Refusal("unknown_marker", f"no marker '{name}' (markers: {known})")
    return mk


@contextmanager
def placed_at(rules: Rules, name: str, mk: Marker) -> Iterator[None]:
    """The mission as if marker `name` were `mk` (to compute the values bound
    to it), then as it was (the events apply the change)."""
    markers = rules.mission.markers
    old = markers.get(name)
    markers[name] = mk
    try:
        yield
    finally:
        if old is None:
            del markers[name]
        else:
            markers[name] = old


def bound(rules: Rules, name: str) -> Iterator[tuple[str, SkillInstance, str]]:
    """(robot, skill, parameter) of every parameter bound to marker `name`."""
    for robot, task in rules.mission.tasks.items():
        for s in task:
            for pname, mname in s.bindings.items():
                if mname == name:
                    yield robot, s, pname


def named(rules: Rules, name: str) -> Iterator[tuple[str, SkillInstance, str]]:
    """Skills whose marker-type parameter names marker `name` (not finished)."""
    for robot, s, spec in _unfinished(rules):
        for pname, pspec in spec.params.items():
            if pspec.kind.names_marker and s.params.get(pname) == name:
                yield robot, s, pname


def _unfinished(rules: Rules) -> Iterator[tuple[str, SkillInstance, SkillSpec]]:
    """(robot, skill, its spec) of every skill not finished that its robot's
    type offers."""
    m = rules.mission
    for robot, task in m.tasks.items():
        rtype = m.robots[robot].type if robot in m.robots else ""
        for s in task:
            spec = rules.library.skill_for(rtype, s.skill)
            if spec is not None and s.status not in FINISHED:
                yield robot, s, spec


def add_marker(rules: Rules, op: MarkerAdd) -> Change:
    if op.name in rules.mission.markers:
        raise Refusal("exists", f"a marker named '{op.name}' exists already")
    events: list[ev.Event] = [ev.MarkerSet(name=op.name, marker=op.marker)]
    return Change(events, [], {}, MarkerDelete(name=op.name))


def move_marker(rules: Rules, op: MarkerMove) -> Change:
    old = marker(rules, op.name)
    new = _moved(op.name, old, op.value)
    events: list[ev.Event] = [ev.MarkerSet(name=op.name, marker=new)]
    with placed_at(rules, op.name, new):
        followed, notes, stale = _follow(rules, op.name)
    return Change(
        events + followed, notes, {"stale": stale}, MarkerMove(name=op.name, value=_value(old))
    )


def _moved(name: str, old: Marker, value: MarkerValue) -> Marker:
    """Marker `old` at `value`, refused if that is not of its kind."""
    if (old.kind == "area") != isinstance(value, list):
        need = "a polygon (a list of positions)" if old.kind == "area" else f"a {old.kind}"
        raise Refusal("bad_marker", f"marker '{name}' is a {old.kind} marker: move it to {need}")
    data = old.model_dump()
    if isinstance(value, list):
        data["area"] = [p.model_dump() for p in value]
    elif old.kind == "pose":
        data["pose"] = value.model_dump()
    else:
        data["position"] = {k: getattr(value, k) for k in ("x", "y", "z")}
    return type(old).model_validate(data)


def _value(mk: Marker) -> MarkerValue:
    if isinstance(mk, AreaMarker):
        return mk.area
    if isinstance(mk, PoseMarker):
        return mk.pose
    return mk.position


def _follow(rules: Rules, name: str) -> tuple[list[ev.Event], list[str], list[str]]:
    """Bound values follow the moved marker in the plan: (events, notes, skills
    that keep the old value: synchronized, or being synchronized)."""
    events: list[ev.Event] = []
    notes: list[str] = []
    stale: list[str] = []
    for robot, s, pname in bound(rules, name):
        if s.status == Status.IDLE:
            params = rules.check_params(robot, s.skill, s.params, s.bindings, skill_id=s.id)
            if params != s.params:
                events.append(ev.SkillEdited(id=s.id, params=params))
            if s.id in rules.locked:  # left with the old value; its ack will say so
                stale.append(s.id)
                notes.append(
                    f"{robot}: {s.display()} is being synchronized with the old value of "
                    f"{name} for '{pname}'; unsynchronize it once it is queued to update"
                )
        elif s.status not in FINISHED:
            stale.append(s.id)
            notes.append(
                f"{robot}: {s.display()} ({s.status.value}) still uses the old value of "
                f"{name} for '{pname}'; unsynchronize it to update"
            )
    return events, notes, stale


def rename_marker(rules: Rules, op: MarkerRename) -> Change:
    mk = marker(rules, op.name)
    if op.new_name in rules.mission.markers:
        raise Refusal("exists", f"a marker named '{op.new_name}' exists already")
    events: list[ev.Event] = [
        ev.MarkerSet(name=op.new_name, marker=mk),
        ev.MarkerRemoved(name=op.name),
    ]
    for robot, s, pname in named(rules, op.name):
        if s.status != Status.IDLE:
            raise Refusal(
                "marker_in_use",
                f"cannot rename marker '{op.name}': {s.display()} on {robot} is "
                f"{s.status.value} and names it in '{pname}'",
                robot=robot,
                skill=s.id,
            )
        events.append(ev.SkillEdited(id=s.id, params={**s.params, pname: op.new_name}))
    # a binding names where a value came from, not the value: follow the
    # rename on the plan and the queue; the execution log stays as it ran
    for _, s, pname in bound(rules, op.name):
        if s.status in FINISHED:
            continue
        events.append(ev.SkillEdited(id=s.id, bindings={**s.bindings, pname: op.new_name}))
    return Change(events, [], {}, MarkerRename(name=op.new_name, new_name=op.name))


def delete_marker(rules: Rules, op: MarkerDelete) -> Change:
    mk = marker(rules, op.name)
    for robot, s, pname in named(rules, op.name):
        raise Refusal(
            "marker_in_use",
            f"cannot delete marker '{op.name}': {s.display()} on {robot} names it in "
            f"'{pname}'; change that first",
            robot=robot,
            skill=s.id,
        )
    events: list[ev.Event] = [ev.MarkerRemoved(name=op.name)]
    unbound: list[tuple[str, str]] = []
    for robot, s, pname in bound(rules, op.name):
        if s.status in FINISHED:
            continue  # the execution log keeps the name it ran with
        if s.status != Status.IDLE:
            raise Refusal(
                "marker_in_use",
                f"cannot delete marker '{op.name}': {s.display()} on {robot} is "
                f"{s.status.value} and uses it for '{pname}'",
                robot=robot,
                skill=s.id,
            )
        bindings = {k: v for k, v in s.bindings.items() if v != op.name}
        events.append(ev.SkillEdited(id=s.id, bindings=bindings))  # keeps its values
        unbound.append((s.id, pname))
    return Change(events, [], {}, RestoreMarker(name=op.name, marker=mk, bindings=unbound))


def restore_marker(rules: Rules, op: RestoreMarker) -> Change:
    if op.name in rules.mission.markers:
        raise Refusal("exists", f"a marker named '{op.name}' exists already")
    events: list[ev.Event] = [ev.MarkerSet(name=op.name, marker=op.marker)]
    with placed_at(rules, op.name, op.marker):
        for sid, pname in op.bindings:
            found = rules.mission.find(sid)
            if found is None or found[2].status != Status.IDLE or sid in rules.locked:
                continue  # gone or on a robot since: leave it as it is
            robot, _, s = found
            bindings = {**s.bindings, pname: op.name}
            params = rules.check_params(robot, s.skill, s.params, bindings, skill_id=sid)
            events.append(ev.SkillEdited(id=sid, bindings=bindings, params=params))
    return Change(events, [], {}, MarkerDelete(name=op.name))


RULES: dict[type[Any], Rule] = {
    MarkerAdd: add_marker,
    MarkerMove: move_marker,
    MarkerRename: rename_marker,
    MarkerDelete: delete_marker,
    RestoreMarker: restore_marker,
}
