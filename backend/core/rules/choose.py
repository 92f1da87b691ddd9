"""Markers chosen on board: a robot, not the ground, chooses their place.

At sync a skill bound to such a marker goes up with its rule (`Enqueue.choose`)
and the ground's estimate in `params`; the robot chooses before the handler
runs and says where with the skill's report (`Report.chosen`). The first
report of a choice sets the marker (an event like a move: journaled,
replayed), idle skills bound to it follow; a later report of another place
is an alert, never a silent change (docs/robots.md "Places chosen on board").
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from backend.core import events as ev
from backend.core.alerts import AlertKind, Level, RaisedAlert
from backend.core.model import (
    FINISHED,
    ChooseOnBoard,
    ChooseRule,
    Chosen,
    Marker,
    Pose,
    PoseMarker,
    Position,
    PositionMarker,
    SkillInstance,
    Status,
)
from backend.core.ops import Report
from backend.core.rules.base import Rules
from backend.core.rules.markers import bound, placed_at

NEAR_M = 0.5  # metres two robots' choices may differ by and still agree


def on_board(
    rules: Rules, robot: str, skills: Sequence[SkillInstance]
) -> dict[str, dict[str, ChooseOnBoard]]:
    """Skill id -> its parameters bound to a marker still to be chosen: the
    rule, and the other robots bound to it (they agree robot to robot)."""
    markers = rules.mission.markers
    out: dict[str, dict[str, ChooseOnBoard]] = {}
    for s in skills:
        for pname, mname in s.bindings.items():
            rule = _still_to_choose(markers.get(mname))
            if rule is None:
                continue
            team = sorted(r for r in bound_robots(rules, mname) if r != robot)
            out.setdefault(s.id, {})[pname] = ChooseOnBoard(marker=mname, rule=rule, team=team)
    return out


def _still_to_choose(mk: Marker | None) -> ChooseRule | None:
    """Its rule while no robot chose it (once chosen, its place goes up like any value)."""
    if isinstance(mk, PoseMarker | PositionMarker) and mk.to_choose:
        return mk.choose
    return None


def bound_robots(rules: Rules, marker: str) -> set[str]:
    """The robots with an unfinished skill bound to `marker`."""
    return {
        robot
        for robot, task in rules.mission.tasks.items()
        for s in task
        if s.status not in FINISHED and marker in s.bindings.values()
    }


def reported(rules: Rules, op: Report) -> tuple[list[ev.Event], list[RaisedAlert]]:
    """The markers a report says its robot chose: each set once, by the first
    report; a different place later is an alert (the marker stays)."""
    events: list[ev.Event] = []
    alerts: list[RaisedAlert] = []
    for name, pose in op.chosen.items():
        mk = rules.mission.markers.get(name)
        if not isinstance(mk, PoseMarker | PositionMarker) or mk.choose is None:
            alerts.append(
                _alert(
                    op,
                    f"{op.robot} reported choosing marker '{name}', which is "
                    "not a marker chosen on board: ignored",
                    "warning",
                )
            )
            continue
        if mk.chosen is not None:
            if _far(place(mk), pose):
                alerts.append(
                    _alert(
                        op,
                        f"{op.robot} chose {name} at {xy(pose)} for {op.id}, "
                        f"but {mk.chosen.robot} chose it at {xy(place(mk))}: the "
                        "marker stays where it was first chosen",
                        "warning",
                    )
                )
            continue
        chosen = Chosen(robot=op.robot, skill=op.id, at=op.at)
        new = placed(mk, pose, chosen)
        events.append(ev.MarkerSet(name=name, marker=new))
        events += _follow(rules, name, new)
        alerts.append(
            _alert(
                op,
                f"{op.robot} chose {name} on board at {xy(pose)} "
                f"({mk.choose.describe()}) for {op.id}",
                "info",
            )
        )
    return events, alerts


def _follow(rules: Rules, name: str, new: Marker) -> list[ev.Event]:
    """Idle skills bound to the marker take its chosen place (those on their
    way to a robot, or on it, choose it there)."""
    idle = {s.id: (robot, s) for robot, s, _p in bound(rules, name) if _follows(rules, s)}
    with placed_at(rules, name, new):
        edits = [
            (s, rules.check_params(robot, s.skill, s.params, s.bindings, skill_id=s.id))
            for robot, s in idle.values()
        ]
    return [ev.SkillEdited(id=s.id, params=p) for s, p in edits if p != s.params]


def _follows(rules: Rules, s: SkillInstance) -> bool:
    return s.status == Status.IDLE and s.id not in rules.locked


def placed(mk: PoseMarker | PositionMarker, pose: Pose, chosen: Chosen) -> Marker:
    if isinstance(mk, PoseMarker):
        return mk.model_copy(update={"pose": pose, "chosen": chosen}, deep=True)
    where = Position(x=pose.x, y=pose.y, z=pose.z)
    return mk.model_copy(update={"position": where, "chosen": chosen}, deep=True)


def place(mk: PoseMarker | PositionMarker) -> Pose:
    if isinstance(mk, PoseMarker):
        return mk.pose
    return Pose(x=mk.position.x, y=mk.position.y, z=mk.position.z)


def _far(a: Pose, b: Pose) -> bool:
    return math.hypot(a.x - b.x, a.y - b.y) > NEAR_M


def xy(p: Pose | Position) -> str:
    return f"({p.x:.1f}, {p.y:.1f})"


def _alert(op: Report, message: str, level: Level) -> RaisedAlert:
    return RaisedAlert(
        message=message, robot=op.robot, skill=op.id, level=level, kind=AlertKind.CHOSEN
    )
