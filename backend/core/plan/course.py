"""Each robot's plan walked skill by skill: where it is, its battery, how long
each skill takes — independent of time and of the other robots (barriers and
the clock are the forecast's).

A course starts from the robot's last telemetry (position, battery, progress
of the skill it executes); without telemetry, from where its last finished
skill with a goal took it (else from home, if known), at an assumed full
battery. Legs are cached by
skill object (`apply_events` replaces a skill object whenever it changes),
start place and map version, so an event recomputes only what it touched.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

from backend.core.library import BatteryModel, Library, RobotType
from backend.core.model import ACTIVE, FINISHED, SkillInstance
from backend.core.plan.branches import TRIGGERS, BranchCost, Costing, assumed, cost, worst
from backend.core.plan.geometry import Point, point_of
from backend.core.plan.inputs import PlanInputs, RobotNow
from backend.core.plan.legs import Leg, build_leg, charge_s

QUANTUM_M = 0.25  # start places closer than this share a cached leg


@dataclass(frozen=True, slots=True)
class Step:
    """One unfinished skill of a robot's course."""

    skill: SkillInstance
    leg: Leg | None  # None: the library does not know the skill for this robot
    start: Point | None  # where the robot starts it
    busy_s: float  # robot seconds still to go, charging included
    travel_s: float  # of which travelling (first)
    remaining: float  # share of the skill still to do (below 1 for the active one)
    battery_start: float | None
    battery_min: float | None  # lowest level during the skill
    battery_end: float | None
    # its on_timeout, when the forecast says it outlasts its timeout: the plan
    # (busy_s and the battery count it; backend.core.plan.branches)
    assumed: BranchCost | None = None
    # of its branches that run skills, the one leaving the battery lowest
    worst: BranchCost | None = None


@dataclass(frozen=True, slots=True)
class Course:
    robot: str
    robot_type: RobotType | None
    steps: tuple[Step, ...]  # the unfinished skills, in order (the active one first)
    battery: BatteryModel | None  # the robot type's model (None: no battery)
    battery_assumed: bool  # no telemetry: a full battery was assumed
    now: RobotNow | None
    offsets: tuple[float, ...]  # robot seconds before each step; one more: the total
    index: dict[str, int]  # skill id -> its step


# what a leg was built from besides its skill: the start (quantized), the
# map's version and home; a leg is built again when one of them changed
_LegBasis = tuple[tuple[int, int] | None, int, Point | None]


class LegCache:
    """skill id -> (the skill object, what its leg was built from, its leg)."""

    def __init__(self) -> None:
        self._legs: dict[str, tuple[SkillInstance, _LegBasis, Leg]] = {}

    def leg(
        self,
        library: Library,
        rt: RobotType,
        robot_type: str,
        s: SkillInstance,
        start: Point | None,
        inputs: PlanInputs,
    ) -> Leg | None:
        key = None if start is None else (round(start[0] / QUANTUM_M), round(start[1] / QUANTUM_M))
        home = inputs.home_point()
        basis = (key, inputs.site_version(), home)
        hit = self._legs.get(s.id)
        if hit is not None and hit[0] is s and hit[1] == basis:
            return hit[2]
        spec = library.skill_for(robot_type, s.skill)
        if spec is None:
            return None
        leg = build_leg(rt, robot_type, spec, s.params, start, home, inputs.site)
        self._legs[s.id] = (s, basis, leg)
        return leg

    def size(self) -> int:
        return len(self._legs)

    def forget(self, keep: set[str]) -> None:
        """Drop the legs of skills not in `keep` (deleted ones)."""
        for sid in [k for k in self._legs if k not in keep]:
            del self._legs[sid]


def _last_place(library: Library, robot_type: str, task: Sequence[SkillInstance]) -> Point | None:
    """Where the last finished skill with a goal took the robot."""
    for s in reversed(task):
        if s.status not in FINISHED:
            continue
        spec = library.skill_for(robot_type, s.skill)
        if spec is not None and spec.duration.goal_param:
            p = point_of(s.params.get(spec.duration.goal_param))
            if p is not None:
                return p
    return None


def _progress(s: SkillInstance, now: RobotNow | None) -> float:
    if now is not None and now.skill == s.id and now.progress is not None:
        return min(1.0, max(0.0, now.progress))
    return 0.0


def walk(
    library: Library,
    robot: str,
    robot_type: str,
    task: Sequence[SkillInstance],
    inputs: PlanInputs,
    legs: LegCache,
    markers: Mapping[str, Any] | None = None,
) -> Course:
    """The robot's unfinished skills, one after the other (`markers`: the
    mission's, for the places its contingency branches go to)."""
    rt = library.robot_types.get(robot_type)
    costing = Costing(library, rt, robot_type, markers or {}, inputs) if rt is not None else None
    now = inputs.robots.get(robot)
    battery_model = rt.battery if rt is not None else None
    pos = _start(library, robot_type, task, inputs, now)
    level, assumed = _level_now(battery_model, now)
    steps: list[Step] = []
    offsets = [0.0]
    for s in (s for s in task if s.status not in FINISHED):
        leg = legs.leg(library, rt, robot_type, s, pos, inputs) if rt is not None else None
        step = _step(rt, s, leg, pos, level, _progress(s, now) if s.status in ACTIVE else 0.0)
        step = _contingent(costing, step) if costing is not None else step
        steps.append(step)
        offsets.append(offsets[-1] + step.busy_s)
        level = step.battery_end
        pos = _place_after(step, pos)
    index = {step.skill.id: i for i, step in enumerate(steps)}
    return Course(robot, rt, tuple(steps), battery_model, assumed, now, tuple(offsets), index)


def _start(
    library: Library,
    robot_type: str,
    task: Sequence[SkillInstance],
    inputs: PlanInputs,
    now: RobotNow | None,
) -> Point | None:
    """Where the robot is: as it last said, else where its last goal took
    it, else home (where robots start)."""
    if now is not None and now.position is not None:
        return now.position
    return _last_place(library, robot_type, task) or inputs.home_point()


def _level_now(model: BatteryModel | None, now: RobotNow | None) -> tuple[float | None, bool]:
    """(the battery now, whether a full one is assumed: no telemetry); None: no battery."""
    if model is None:
        return None, False
    if now is not None and now.battery is not None:
        return now.battery, False
    return 1.0, True


def _place_after(step: Step, pos: Point | None) -> Point | None:
    """Where the robot is once the step is done: where its assumed branch ended, else its leg."""
    if step.assumed is not None:
        return step.assumed.end
    return step.leg.end if step.leg is not None else pos


def _contingent(c: Costing, step: Step) -> Step:
    """The step with its branches' costs: the worst for the battery, and the
    on_timeout the forecast assumes when the skill outlasts its timeout."""
    p = step.skill.policies
    if p.on_failure == "halt" and p.on_timeout == "halt" and p.timeout is None:
        return step  # most skills: nothing to cost
    costs = [b for t in TRIGGERS if (b := cost(c, t, step)) is not None]
    step = replace(step, worst=worst(costs))
    plan = assumed(c, step)
    if plan is None:
        return step
    return replace(
        step,
        busy_s=plan.total_s,
        battery_min=plan.battery_min,  # the skill's share, then the branch: the lowest
        battery_end=plan.battery_end,
        assumed=plan,
    )


def _step(
    rt: RobotType | None,
    s: SkillInstance,
    leg: Leg | None,
    start: Point | None,
    level: float | None,
    done: float,
) -> Step:
    """A skill's step from `start` at battery `level`, `done` of it done already."""
    if leg is None or rt is None:
        return Step(s, leg, start, 0.0, 0.0, 1.0 - done, level, level, level)
    rest = 1.0 - done
    # the active skill's travel is measured from where the robot is now; its work scales
    travel_s = leg.travel_s
    work_s = leg.work_s * rest
    used = leg.per_s * (travel_s + work_s) + leg.per_metre * leg.travel_m
    if level is None:
        return Step(s, leg, start, travel_s + work_s, travel_s, rest, None, None, None)
    low = level - used
    charging = charge_s(rt, leg, max(0.0, low))
    end = max(low, leg.charge_to) if leg.charge_to is not None and charging > 0 else low
    return Step(s, leg, start, travel_s + work_s + charging, travel_s, rest, level, low, end)
