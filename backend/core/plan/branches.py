"""What a skill's contingency (policies on_failure / on_timeout) costs the
plan: the branch the forecast assumes, and the worst case for the battery.

- **End times take the nominal path**: every skill succeeds in its forecast
  time, except one whose `timeout` is shorter than that (the warning
  `contingency.timeout_short`): then its `on_timeout` is the plan, and the
  course counts the timeout, then the branch's skills (a fallback's; a goto's
  drive to its marker) from where the robot stopped, with their energy; the
  next skill starts from where the branch ended. (`continue` runs the skill
  to its end; skip and halt stop it at the timeout.)
- **The battery is also checked on the worst path** of every skill whose
  branch runs skills: the branch starts as late as it can, at the skill's end
  (a failure there: its whole energy spent) or at its timeout when that
  comes first, and runs from there (`contingency.branch_energy` warns below
  the reserve).

A failure is never assumed for the end time: a forecast that assumed every
fallback would say nothing about the plan as meant.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

from backend.core.contingency import branch_skills, branch_text
from backend.core.library import Library, RobotType, check_params
from backend.core.plan.geometry import Point
from backend.core.plan.inputs import PlanInputs
from backend.core.plan.legs import build_leg, charge_s

Trigger = Literal["failure", "timeout"]
TRIGGERS: tuple[Trigger, ...] = ("failure", "timeout")


@dataclass(frozen=True, slots=True)
class BranchCost:
    """A contingency branch that runs skills, costed from where it would start."""

    trigger: Trigger
    text: str  # branch_text: 'goto@POI-A', 'recharge@Lander'
    before_s: float  # robot seconds of the skill itself before the branch starts
    busy_s: float  # robot seconds of the branch's skills
    battery_min: float | None  # lowest level on this path (the skill's share, then the branch)
    battery_end: float | None
    end: Point | None  # where the robot is once the branch ran
    skill_s: float = 0.0  # robot seconds the skill itself would take, to its end

    @property
    def total_s(self) -> float:
        return self.before_s + self.busy_s


@dataclass(frozen=True)
class Costing:
    """What costing a robot's branches needs besides the step."""

    library: Library
    rt: RobotType
    robot_type: str
    markers: Mapping[str, Any]
    inputs: PlanInputs


@dataclass(frozen=True, slots=True)
class Started:
    """Where a branch starts: after `before_s` of the skill, at this place and level."""

    before_s: float
    at: Point | None
    level: float | None


def timed_out(skill: Any, busy_s: float, remaining: float) -> bool:
    """The forecast says it cannot finish in its timeout (a skill not started yet)."""
    timeout = skill.policies.timeout
    return timeout is not None and remaining == 1 and busy_s > timeout


def cost(c: Costing, trigger: Trigger, step: Any) -> BranchCost | None:
    """The branch of `trigger` of a course step, costed; None when it runs no skills."""
    branch = getattr(step.skill.policies, f"on_{trigger}")
    skills = branch_skills(branch, c.library, c.robot_type)
    if isinstance(skills, str) or not skills:
        return None
    at = _start(step, trigger)
    run = _Run(at.at, at.level, at.level)
    for f in skills:
        run.add(c, f)
    text = branch_text(branch)
    return BranchCost(
        trigger, text, at.before_s, run.busy_s, run.low, run.level, run.at, step.busy_s
    )


@dataclass
class _Run:
    """A branch's skills one after the other: where, the battery, the time."""

    at: Point | None
    level: float | None
    low: float | None
    busy_s: float = 0.0

    def add(self, c: Costing, f: Any) -> None:
        spec = c.library.skill_for(c.robot_type, f.skill)
        if spec is None:  # refused where it was set (bad_contingency): not costed
            return
        values, _problems = check_params(
            c.library,
            c.robot_type,
            f.skill,
            f.params,
            f.bindings,
            markers=dict(c.markers),
            robots=set(),
        )
        leg = build_leg(
            c.rt, c.robot_type, spec, values, self.at, c.inputs.home_point(), c.inputs.site
        )
        self.busy_s += leg.busy_s
        self.at = leg.end if leg.end is not None else self.at
        if self.level is not None:
            self._spend(c, leg, self.level)

    def _spend(self, c: Costing, leg: Any, level: float) -> None:
        """The battery through one leg, and the time it charges (a recharge)."""
        low = level - leg.energy
        charging = charge_s(c.rt, leg, max(0.0, low))
        self.busy_s += charging
        self.low = min(low, self.low if self.low is not None else low)
        self.level = max(low, leg.charge_to) if leg.charge_to is not None and charging > 0 else low


def assumed(c: Costing, step: Any) -> BranchCost | None:
    """The on_timeout path the end time assumes when the forecast says the
    skill outlasts its timeout (None: it does not, or `continue` runs it on)."""
    on_timeout = step.skill.policies.on_timeout
    if on_timeout == "continue" or not timed_out(step.skill, step.busy_s, step.remaining):
        return None
    found = cost(c, "timeout", step)
    if found is not None:
        return found
    at = _start(step, "timeout")  # skip / halt: stopped at its timeout, where it was
    text = branch_text(on_timeout)
    return BranchCost("timeout", text, at.before_s, 0.0, at.level, at.level, at.at, step.busy_s)


def _start(step: Any, trigger: Trigger) -> Started:
    """Where and at what level a branch starts, at the latest: the skill's
    end, or its timeout when that comes first (and stops it: not `continue`,
    unless it is the timeout's own branch)."""
    cut = _cut_at(step, trigger)
    if cut is None:
        return Started(step.busy_s, _end_of(step), step.battery_min)
    return Started(cut, _stopped_at(step, cut), _level_at(step, cut / step.busy_s))


def _cut_at(step: Any, trigger: Trigger) -> float | None:
    """The timeout, when it stops the skill before its forecast end."""
    p = step.skill.policies
    if p.timeout is None or not 0 < p.timeout < step.busy_s:
        return None
    return None if trigger == "failure" and p.on_timeout == "continue" else float(p.timeout)


def _level_at(step: Any, share: float) -> float | None:
    if step.battery_start is None or step.battery_min is None:
        return None
    return float(step.battery_start - (step.battery_start - step.battery_min) * share)


def _end_of(step: Any) -> Point | None:
    return step.leg.end if step.leg is not None else step.start  # type: ignore[no-any-return]


def _stopped_at(step: Any, seconds: float) -> Point | None:
    """Where a skill stopped after `seconds`: along its travel (a straight
    line's share), else where it works."""
    if not _travels(step):
        return _end_of(step)
    k = min(1.0, seconds / step.travel_s)
    (x0, y0), (x1, y1) = step.start, step.leg.goal
    return (x0 + (x1 - x0) * k, y0 + (y1 - y0) * k)


def _travels(step: Any) -> bool:
    leg = step.leg
    return leg is not None and leg.goal is not None and step.start is not None and step.travel_s > 0


def worst(costs: list[BranchCost]) -> BranchCost | None:
    """The branch that leaves the battery lowest (else the longest)."""
    if not costs:
        return None
    return min(costs, key=lambda b: (_lowest(b), -b.total_s))


def _lowest(b: BranchCost) -> float:
    return b.battery_min if b.battery_min is not None else math.inf
