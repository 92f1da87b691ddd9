"""Rules of the team: robots that join the mission at runtime and robots
that are retired from it (issue 30).

A robot joins with a type the library knows (the server announces a robot
that registers under a new name; an operator adds it). A retired robot gets
no new syncs; what it holds is taken back (by its uplink while it is
reachable, else on the ground, saying so) and its unsynchronized plan awaits
reassignment (`backend.core.rules.reassign`); its log stays.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

from backend.core import events as ev
from backend.core.alerts import AlertKind, RaisedAlert
from backend.core.library import Library
from backend.core.model import ACTIVE, CommandState, RobotSpec, Status
from backend.core.ops import AddRobot, RetireRobot, Unsync
from backend.core.rules import reassign, uplink
from backend.core.rules.base import Change, Refusal, Rule, Rules


@runtime_checkable
class Reach(Protocol):
    """Whether a robot can be told anything now (the server's robot link)."""

    def reachable(self, robot: str) -> bool: ...


def unknown_type(library: Library, robot: str, robot_type: str) -> str | None:
    """The sentence refusing a robot of a type the library lacks (None: known)."""
    if robot_type in library.robot_types:
        return None
    known = ", ".join(library.robot_types) or "none"
    return (
        f"robot {robot} is a '{robot_type}', a type the library '{library.name}' does not "
        f"have (its types: {known}): add robot type '{robot_type}' (its skills, battery) to "
        "the library, or register the robot as one of those"
    )


def add_robot(rules: Rules, op: AddRobot) -> Change:
    spec = rules.mission.robots.get(op.name)
    if spec is not None:
        state = f"retired ({spec.retired})" if spec.retired else "in service"
        raise Refusal(
            "robot_exists",
            f"robot {op.name} is part of the mission already ({spec.type}, {state})",
            robot=op.name,
        )
    why = unknown_type(rules.library, op.name, op.type)
    if why is not None:
        raise Refusal("unknown_robot_type", why, robot=op.name)
    notes = _lacking(rules, op.name, op.type)
    alert = RaisedAlert(
        level="info",
        kind=AlertKind.TEAM,
        robot=op.name,
        message=f"robot {op.name} ({op.type}) joined the mission: its plan is empty",
    )
    events: list[ev.Event] = [
        ev.RobotAdded(name=op.name, spec=RobotSpec(type=op.type, description=op.description))
    ]
    return Change(events, notes, {"robot": op.name, "type": op.type}, None, alerts=(alert,))


def _lacking(rules: Rules, robot: str, robot_type: str) -> list[str]:
    """A note when the robot's manifest lacks skills its type has (it registered)."""
    offered = rules.offers.offered(robot) if rules.offers is not None else None
    if offered is None:
        return []
    missing = [s for s in rules.library.skills_of(robot_type) if s not in offered]
    if not missing:
        return []
    return [f"{robot} does not offer {', '.join(missing)}: its syncs of them will be refused"]


def reachable(rules: Rules, robot: str) -> bool:
    """Unknown (no robot link, as in tests of the rules): reachable, so the
    uplink takes its skills back when it hears it."""
    return not isinstance(rules.offers, Reach) or rules.offers.reachable(robot)


def retire_robot(rules: Rules, op: RetireRobot) -> Change:
    rules.robot_type(op.name)
    spec = rules.mission.robots[op.name]
    if spec.retired:
        raise Refusal(
            "retired", f"robot {op.name} is retired already ({spec.retired})", robot=op.name
        )
    events: list[ev.Event] = [ev.RobotRetired(name=op.name, reason=op.reason)]
    if reachable(rules, op.name):
        events += _unsync_by_uplink(rules, op)
        how = "by its uplink"
    else:
        events += _take_back(rules, op.name)
        how = "on the ground (it is out of reach: it drops them when it registers again)"
    task = rules.mission.tasks.get(op.name, [])
    plan = [s.id for s in task if s.status in (Status.IDLE, Status.IDLE_SYNCHRONIZED)]
    plan[:0] = [e.skill.id for e in events if isinstance(e, ev.SkillAdded)]
    alert = RaisedAlert(
        kind=AlertKind.TEAM,
        robot=op.name,
        message=f"robot {op.name} retired ({op.reason}); {len(plan)} skill(s) to reassign",
    )
    value = {"robot": op.name, "to_reassign": plan}
    notes = _retired_notes(op.name, how, plan) + reassign.held(rules, op.name)
    return Change(events, notes, value, None, alerts=(alert,))


def _retired_notes(robot: str, how: str, plan: list[str]) -> list[str]:
    notes = [f"{robot} retired: no new syncs; its log stays; queued skills are taken back {how}"]
    if plan:
        notes.append(
            f"its plan ({', '.join(plan)}) awaits reassignment: "
            f"'Give to…' in a console, or missionctl ctl reassign --from {robot} --to ROBOT"
        )
    return notes


def _unsync_by_uplink(rules: Rules, op: RetireRobot) -> list[ev.Event]:
    task = rules.mission.tasks.get(op.name, [])
    locked = rules.locked
    if not any(s.status == Status.IDLE_SYNCHRONIZED and s.id not in locked for s in task):
        return []
    return uplink.unsync(rules, Unsync(robot=op.name, expire_s=op.expire_s)).events


def _take_back(rules: Rules, robot: str) -> list[ev.Event]:
    """An unreachable robot's pending commands cancelled, its queued skills idle
    again and its active one failed: the ground cannot know its outcome."""
    now = rules.clock()
    said = f"{robot} was retired while out of reach"
    events: list[ev.Event] = [
        ev.CommandChanged(
            id=c.id,
            state=CommandState.CANCELLED,
            settled=now,
            reason=f"{said}: given up on the ground (if it comes back, its registration "
            "says what it holds)",
        )
        for c in rules.mission.pending_commands(robot)
    ]
    for i, s in enumerate(rules.mission.tasks.get(robot, [])):
        if s.status == Status.IDLE_SYNCHRONIZED:
            info = f"taken back on the ground: {said}"
            events.append(ev.SkillStatusChanged(id=s.id, status=Status.IDLE, info=info, at=now))
        elif s.status in ACTIVE:
            # its next attempt leads the plan to reassign: the work is not lost
            info = f"{said}: its outcome is unknown; {s.retry_id()} is its next attempt"
            events.append(ev.SkillStatusChanged(id=s.id, status=Status.FAILURE, info=info, at=now))
            events.append(ev.SkillAdded(robot=robot, index=i + 1, skill=s.next_attempt()))
    return events


RULES: dict[type[Any], Rule] = {AddRobot: add_robot, RetireRobot: retire_robot}
