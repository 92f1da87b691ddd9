"""Plan checks: what would go wrong with the plan, before it goes up the link.

Each check is a small rule in `RULES`: a stable rule name, a severity
(warning or error) and a function yielding `Hit`s; a finding's id is
`rule:subject` (skill ids, barrier ids, parameter names — stable across
edits), which is what a waiver names. Rules that need the site map (coverage,
terrain) say so and are skipped without one: the mission server has no map
(and no telemetry), consoles and `ctl check` do.

Errors block a sync of the skills they name unless waived (backend.core.plan.gate).
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterator, Mapping
from dataclasses import dataclass
from typing import Literal

from backend.core.library import Library, SkillSpec
from backend.core.model import FINISHED, Mission, SkillInstance, Status, Waiver
from backend.core.plan.contingency_checks import (
    after_deadlock,
    branch_energy,
    goto_impassable,
    timeout_short,
)
from backend.core.plan.course import Course, LegCache, Step, walk
from backend.core.plan.forecast import Forecast
from backend.core.plan.geometry import Point, area, distance, point_of, self_intersecting
from backend.core.plan.hit import Hit
from backend.core.plan.inputs import PlanInputs, SiteMap
from backend.core.plan.order import BarrierAnalysis, analyse

Severity = Literal["warning", "error"]
MIN_AREA_M2 = 1.0  # an area smaller than this is a line or a point


@dataclass(frozen=True, slots=True)
class Finding:
    id: str  # "<rule>:<subject>": what a waiver names
    rule: str
    severity: Severity
    message: str
    robot: str | None = None
    skills: tuple[str, ...] = ()
    waiver: Waiver | None = None

    @property
    def blocking(self) -> bool:
        return self.severity == "error" and self.waiver is None


@dataclass
class CheckContext:
    mission: Mission
    library: Library
    inputs: PlanInputs
    courses: Mapping[str, Course]
    barriers: BarrierAnalysis

    @property
    def site(self) -> SiteMap | None:
        return self.inputs.site


@dataclass(frozen=True)
class CheckRule:
    rule: str
    severity: Severity
    summary: str  # one line for a person (help, docs)
    find: Callable[[CheckContext], Iterator[Hit]]
    needs_site: bool = False


def _pct(x: float) -> str:
    return f"{x * 100:.0f}%"


def _at(p: tuple[float, float] | None) -> str:
    return "an unknown place" if p is None else f"({p[0]:.0f}, {p[1]:.0f})"


# -- barriers ----------------------------------------------------------------------


def _deadlocks(ctx: CheckContext) -> Iterator[Hit]:
    b = ctx.barriers
    for cycle in b.cycles:
        skills = tuple(sid for bid in cycle for sid in b.pending[bid].values())
        yield Hit(
            "+".join(cycle),
            f"barriers {', '.join(cycle)} can never be passed: {'; '.join(_waits(b, cycle))}. "
            "Reorder these skills or remove one of the barriers",
            skills=skills,
        )


def _waits(b: BarrierAnalysis, cycle: list[str]) -> list[str]:
    """Why each robot of a deadlock waits, sorted: which barrier of the cycle
    it must pass before it reaches another."""
    waits = []
    for waiting in cycle:
        for holding in cycle:
            robot = b.held_by.get((waiting, holding))
            if robot is not None:
                waits.append(
                    f"{robot} must pass {holding} ({b.skill_of(holding, robot)}) before it "
                    f"reaches {waiting} ({b.skill_of(waiting, robot)})"
                )
    return sorted(waits)


def _orphans(ctx: CheckContext) -> Iterator[Hit]:
    b = ctx.barriers
    for bid, gone in sorted(b.orphaned.items()):
        waiting = ", ".join(f"{sid} ({r})" for r, sid in sorted(b.pending[bid].items()))
        went = ", ".join(f"{sid} ({r})" for r, sid in gone)
        yield Hit(
            bid,
            f"barrier {bid}: {waiting} would wait forever, since {went} already went through "
            f"it; remove the barrier (ctl unbarrier {bid}) or take the waiting skill out of it",
            skills=tuple(b.pending[bid].values()),
        )


# -- energy ------------------------------------------------------------------------


def _segments(course: Course) -> Iterator[list[Step]]:
    """The course cut after each skill that charges."""
    seg: list[Step] = []
    for step in course.steps:
        seg.append(step)
        if step.leg is not None and step.leg.charge_to is not None:
            yield seg
            seg = []
    if seg:
        yield seg


def _energy(ctx: CheckContext, low: Callable[[Course, float], bool], what: str) -> Iterator[Hit]:
    for robot, course in ctx.courses.items():
        if course.battery is None:
            continue
        assumed = " (assuming a full battery now: no telemetry)" if course.battery_assumed else ""
        for seg in _segments(course):
            step = _first_low(course, seg, low)
            if step is None or step.battery_min is None:
                continue
            yield Hit(
                step.skill.id,
                f"{robot}: battery predicted at {_pct(max(0.0, step.battery_min))} during "
                f"{step.skill.display()}, {what} {_before(seg)}{assumed}; add a recharge before "
                "it, or make the skills before it shorter",
                robot=robot,
                skills=(step.skill.id,),
            )


def _first_low(
    course: Course, seg: list[Step], low: Callable[[Course, float], bool]
) -> Step | None:
    """The first step of a segment whose battery falls `low`."""
    return next((s for s in seg if s.battery_min is not None and low(course, s.battery_min)), None)


def _before(seg: list[Step]) -> str:
    """What ends a segment of the course: the recharge it ends with, or none."""
    last = seg[-1]
    if last.leg is not None and last.leg.charge_to is not None:
        return f"before {last.skill.id} recharges it"
    return "with no recharge planned"


def _empty(ctx: CheckContext) -> Iterator[Hit]:
    def low(c: Course, level: float) -> bool:
        return c.battery is not None and level < c.battery.reserve

    yield from _energy(ctx, low, "below the reserve it stops at")


def _margin(ctx: CheckContext) -> Iterator[Hit]:
    def low(c: Course, level: float) -> bool:
        b = c.battery
        return b is not None and b.reserve <= level < b.margin

    yield from _energy(ctx, low, "below the safety margin")


# -- comms coverage ------------------------------------------------------------------


def _needs_comms(ctx: CheckContext) -> Iterator[Hit]:
    for robot, course in ctx.courses.items():
        for step in course.steps:
            leg = step.leg
            if leg is None or not (leg.work_out or leg.travel_out):
                continue
            why = _why_comms(ctx, step.skill)
            if why is None:
                continue
            yield Hit(
                step.skill.id,
                f"{robot}: {step.skill.display()} is planned out of comms coverage at "
                f"{_at(leg.end)}, and {why}; move it into coverage or deploy a Wi-Fi relay first",
                robot=robot,
                skills=(step.skill.id,),
            )


def _why_comms(ctx: CheckContext, s: SkillInstance) -> str | None:
    """Why a skill must not be out of comms coverage (None: it may be)."""
    spec = ctx.library.skills.get(s.skill)
    if spec is not None and spec.needs_comms:
        return "it needs the operator's link"
    if s.policies.pause_out_of_comms:
        return "it pauses out of comms (its policy), so it would never go on"
    return None


def _out(ctx: CheckContext, step: Step) -> bool:
    site = ctx.site
    end = step.leg.end if step.leg is not None else None
    return site is not None and end is not None and site.covered(*end) is False


def _stranded(ctx: CheckContext) -> Iterator[Hit]:
    for robot, course in ctx.courses.items():
        if not course.steps or course.robot_type is None or course.robot_type.kind == "static":
            continue
        last = course.steps[-1]
        if _out(ctx, last):
            yield Hit(
                last.skill.id,
                f"{robot}'s plan ends at {_at(last.leg.end if last.leg else None)}, out of comms "
                f"coverage, after {last.skill.display()}, with nothing queued to bring it back: "
                "the operator cannot reach it there; end the plan in coverage",
                robot=robot,
                skills=(last.skill.id,),
            )


def _cut_off(ctx: CheckContext) -> Iterator[Hit]:
    for robot, course in ctx.courses.items():
        synced = [s for s in course.steps if s.skill.status != Status.IDLE]
        if not synced or len(synced) == len(course.steps) or not _out(ctx, synced[-1]):
            continue
        last = synced[-1]
        yield Hit(
            last.skill.id,
            f"{robot} will be out of comms coverage after {last.skill.display()}, its last "
            "synchronized skill: the skills planned after it cannot reach it there; synchronize "
            "them before it leaves, or end its synchronized part in coverage",
            robot=robot,
            skills=(last.skill.id,),
        )


def _radio(ctx: CheckContext, robot: str) -> float:
    """Metres the robot's radio reaches another robot without coverage (0: none)."""
    spec = ctx.mission.robots.get(robot)
    rt = ctx.library.robot_types.get(spec.type) if spec is not None else None
    return rt.radio_range_m if rt is not None else 0.0


def _can_talk(ctx: CheckContext, a: tuple[str, Point], b: tuple[str, Point]) -> bool | None:
    """Whether two robots at these places talk: both covered, or within both radios
    (None: the map does not know)."""
    site = ctx.site
    assert site is not None
    ca, cb = site.covered(*a[1]), site.covered(*b[1])
    if ca and cb:
        return True
    radio = min(_radio(ctx, a[0]), _radio(ctx, b[0]))
    if radio > 0 and distance(a[1], b[1]) <= radio:
        return True
    return None if ca is None or cb is None else False


def _arrivals(ctx: CheckContext, members: Mapping[str, str]) -> dict[str, Point]:
    """Where each member robot waits at a barrier: where its course has it when the
    barrier's skill would start."""
    out = {}
    for robot, sid in sorted(members.items()):
        course = ctx.courses.get(robot)
        i = course.index.get(sid) if course is not None else None
        start = course.steps[i].start if course is not None and i is not None else None
        if start is not None:
            out[robot] = start
    return out


def _barrier_out(ctx: CheckContext) -> Iterator[Hit]:
    site = ctx.site
    assert site is not None
    for bid, members in sorted(ctx.barriers.pending.items()):
        if bid in ctx.barriers.stuck:
            continue  # never passed anyway: the barrier rules say why
        places = _arrivals(ctx, members)
        if not _all_talk(ctx, places):
            yield _waiting_out(site, bid, members, places)


def _waiting_out(
    site: SiteMap, bid: str, members: Mapping[str, str], places: Mapping[str, Point]
) -> Hit:
    """A barrier whose robots would wait where they cannot talk: who waits
    out of coverage, where."""
    out = [r for r, p in places.items() if site.covered(*p) is False]
    where = "; ".join(f"{r} waits at {_at(places[r])}" for r in out)
    return Hit(
        bid,
        f"barrier {bid}: {where}, out of comms coverage: partners at a barrier meet only "
        "when they can talk (through the comms network, or within radio range), so "
        f"{' and '.join(sorted(members))} would wait there for ever; plan the skills before "
        "it so that every robot waits in coverage, or deploy a Wi-Fi box there first "
        "(waive this if a box planned before it will cover the place)",
        robot=out[0] if out else None,
        skills=tuple(members[r] for r in sorted(members)),
    )


def _all_talk(ctx: CheckContext, places: Mapping[str, Point]) -> bool:
    """No two of the robots at these places are known not to talk."""
    pairs = [((a, places[a]), (b, places[b])) for a in places for b in places if a < b]
    return all(_can_talk(ctx, a, b) is not False for a, b in pairs)


def _partner_out(ctx: CheckContext) -> Iterator[Hit]:
    member = _barrier_of(ctx)
    for robot, course in ctx.courses.items():
        for step, param, other, end in _with_partner(ctx, robot, course):
            there = _partner_place(ctx, member.get(step.skill.id), other) or end
            if _can_talk(ctx, (robot, end), (other, there)) is not False:
                continue
            yield Hit(
                f"{step.skill.id}/{param}",
                f"{robot}: {step.skill.display()} works with {other} ({param}) at "
                f"{_at(end)}, out of comms coverage: robots talk only through the comms "
                f"network (or within radio range), so it would go on without {other}; deploy "
                "a Wi-Fi box there first, or choose a place in coverage",
                robot=robot,
                skills=(step.skill.id,),
            )


def _with_partner(
    ctx: CheckContext, robot: str, course: Course
) -> Iterator[tuple[Step, str, str, Point]]:
    """(step, parameter, partner, where it works) of the robot's skills that
    work with another robot (the library's `talks_to`) at a known place."""
    for step in course.steps:
        spec = ctx.library.skills.get(step.skill.skill)
        param = spec.talks_to if spec is not None else None
        if param is None:
            continue
        other = step.skill.params.get(param)
        leg = step.leg
        if not isinstance(other, str) or other == robot or leg is None or leg.end is None:
            continue
        yield step, param, other, leg.end


def _barrier_of(ctx: CheckContext) -> dict[str, str]:
    """Skill id -> the pending barrier it is in."""
    return {sid: b for b, ms in ctx.barriers.pending.items() for sid in ms.values()}


def _partner_place(ctx: CheckContext, barrier: str | None, other: str) -> Point | None:
    """Where the partner works on its own skill of the same barrier, if it has one."""
    sid = ctx.barriers.pending.get(barrier, {}).get(other) if barrier is not None else None
    course = ctx.courses.get(other)
    i = course.index.get(sid) if course is not None and sid is not None else None
    leg = course.steps[i].leg if course is not None and i is not None else None
    return leg.end if leg is not None else None


# -- terrain ---------------------------------------------------------------------------


def _goals(ctx: CheckContext) -> Iterator[tuple[str, Step, str, tuple[float, float]]]:
    """(robot, step, goal parameter, goal) of the rovers' skills that travel."""
    for robot, course in _rovers(ctx):
        for step in course.steps:
            spec = ctx.library.skills.get(step.skill.skill)
            if step.leg is None or step.leg.goal is None or spec is None:
                continue
            param = spec.duration.goal_param
            if param is None or spec.duration.goes_home(step.skill.params):
                continue
            if _chosen_on_board(ctx, step.skill, param) is None:  # an estimate: said apart
                yield robot, step, param, step.leg.goal


def _chosen_on_board(ctx: CheckContext, s: SkillInstance, param: str) -> str | None:
    """The marker chosen on board the parameter is bound to, while no robot chose it."""
    name = s.bindings.get(param)
    mk = ctx.mission.markers.get(name) if name is not None else None
    return name if getattr(mk, "to_choose", False) else None


def _estimated(ctx: CheckContext) -> Iterator[Hit]:
    """Skills bound to a place a robot chooses on board: the ground only estimates it."""
    steps = [(robot, step) for robot, course in ctx.courses.items() for step in course.steps]
    for robot, step in steps:
        s = step.skill
        for param, name in sorted((p, _chosen_on_board(ctx, s, p)) for p in s.bindings):
            if name is None:
                continue
            yield Hit(
                f"{s.id}/{param}",
                f"{robot}: {s.display()} goes where {robot} or its team chooses on board "
                f"({name}, {param}): the forecast and checks use the ground's estimate until "
                "a robot reports the place",
                robot=robot,
                skills=(s.id,),
            )


def _rovers(ctx: CheckContext) -> list[tuple[str, Course]]:
    """The courses of the robots that drive on the ground (terrain matters)."""
    return [
        (robot, c)
        for robot, c in ctx.courses.items()
        if c.robot_type is not None and not c.robot_type.flies
    ]


def _impassable(ctx: CheckContext) -> Iterator[Hit]:
    site = ctx.site
    for robot, step, param, goal in _goals(ctx):
        if site is not None and site.passable(*goal) is False:
            yield Hit(
                f"{step.skill.id}/{param}",
                f"{robot}: {step.skill.display()} goes to {_at(goal)} ({param}), which is "
                "impassable ground; move the goal",
                robot=robot,
                skills=(step.skill.id,),
            )


def _no_route(ctx: CheckContext) -> Iterator[Hit]:
    site = ctx.site
    for robot, step, param, goal in _goals(ctx):
        assert step.leg is not None
        if step.leg.no_route and site is not None and site.passable(*goal) is not False:
            yield Hit(
                f"{step.skill.id}/{param}",
                f"{robot}: the map knows no route from {_at(step.start)} to {_at(goal)} "
                f"({step.skill.display()}); move the goal or plan a way round",
                robot=robot,
                skills=(step.skill.id,),
            )


def _unexplored(ctx: CheckContext) -> Iterator[Hit]:
    site = ctx.site
    for robot, step, param, goal in _goals(ctx):
        if site is not None and site.explored(*goal) is False and site.passable(*goal) is not False:
            yield Hit(
                f"{step.skill.id}/{param}",
                f"{robot}: {step.skill.display()} goes to {_at(goal)} ({param}), which nobody "
                "has explored yet: the way or the place may be impassable; explore it first",
                robot=robot,
                skills=(step.skill.id,),
            )


# -- parameters --------------------------------------------------------------------------


def _kinds(ctx: CheckContext) -> dict[tuple[str, str], tuple[list[str], list[str]]]:
    """(robot type, skill) -> (its robot parameters, its area parameters)."""
    return {
        (t, name): _robot_and_area_params(spec)
        for t, rt in ctx.library.robot_types.items()
        for name in rt.skills
        if (spec := ctx.library.skills.get(name)) is not None
    }


def _robot_and_area_params(spec: SkillSpec) -> tuple[list[str], list[str]]:
    """The names of the skill's robot parameters and of its area parameters."""
    robots: list[str] = []
    areas: list[str] = []
    for n, p in spec.params.items():
        if p.type == "robot":
            robots.append(n)
        elif p.type == "area":
            areas.append(n)
    return robots, areas


def _planned(ctx: CheckContext, which: int) -> Iterator[tuple[str, SkillInstance, str]]:
    """(robot, skill, parameter) of the planned skills' robot (0) or area (1) parameters."""
    kinds = _kinds(ctx)
    for robot, course in ctx.courses.items():
        spec = ctx.mission.robots.get(robot)
        if spec is None:
            continue
        for step in course.steps:
            found = kinds.get((spec.type, step.skill.skill))
            for name in found[which] if found is not None else ():
                yield robot, step.skill, name


def _robot_params(ctx: CheckContext) -> Iterator[tuple[str, SkillInstance, str, str]]:
    for robot, s, name in _planned(ctx, 0):
        v = s.params.get(name)
        if isinstance(v, str):
            yield robot, s, name, v


def _self_reference(ctx: CheckContext) -> Iterator[Hit]:
    for robot, s, name, other in _robot_params(ctx):
        if other == robot:
            yield Hit(
                f"{s.id}/{name}",
                f"{robot}: {s.display()} names {robot} itself as its {name}; name another robot",
                robot=robot,
                skills=(s.id,),
            )


def _partner_apart(ctx: CheckContext) -> Iterator[Hit]:
    member = _barrier_of(ctx)
    for robot, s, name, other in _robot_params(ctx):
        if other == robot or other not in ctx.mission.robots:
            continue
        bid = member.get(s.id)
        if bid is not None and other in ctx.barriers.pending[bid]:
            continue
        where = f"its barrier {bid} has none" if bid is not None else "it is in no barrier with one"
        yield Hit(
            f"{s.id}/{name}",
            f"{robot}: {s.display()} names {other} as its {name}, but {where} of {other}'s "
            "skills: they will not be there together; put both skills in a barrier",
            robot=robot,
            skills=(s.id,),
        )


def _areas(ctx: CheckContext) -> Iterator[tuple[str, SkillInstance, str, list[Point]]]:
    for robot, s, name in _planned(ctx, 1):
        v = s.params.get(name)
        pts = [p for p in (point_of(q) for q in v) if p is not None] if isinstance(v, list) else []
        if len(pts) >= 3:
            yield robot, s, name, pts


def _flat_area(ctx: CheckContext) -> Iterator[Hit]:
    for robot, s, name, pts in _areas(ctx):
        if area(pts) < MIN_AREA_M2 and not self_intersecting(pts):
            yield Hit(
                f"{s.id}/{name}",
                f"{robot}: the area {name} of {s.display()} encloses {area(pts):.1f} m² (its "
                "corners lie on a line or a point); give it corners around a region",
                robot=robot,
                skills=(s.id,),
            )


def _crossed_area(ctx: CheckContext) -> Iterator[Hit]:
    for robot, s, name, pts in _areas(ctx):
        if self_intersecting(pts):
            yield Hit(
                f"{s.id}/{name}",
                f"{robot}: the edges of the area {name} of {s.display()} cross each other; list "
                "its corners in order around it",
                robot=robot,
                skills=(s.id,),
            )


def _useless_charge(ctx: CheckContext) -> Iterator[Hit]:
    for robot, course in ctx.courses.items():
        for step in course.steps:
            leg = step.leg
            if leg is None or leg.charge_to is None or step.battery_min is None:
                continue
            if step.battery_min >= leg.charge_to and not course.battery_assumed:
                yield Hit(
                    step.skill.id,
                    f"{robot}: {step.skill.display()} charges to {_pct(leg.charge_to)}, but the "
                    f"battery is predicted at {_pct(step.battery_min)} by then: it will not "
                    "charge; raise its level or drop it",
                    robot=robot,
                    skills=(step.skill.id,),
                )


RULES: tuple[CheckRule, ...] = (
    CheckRule("barrier.deadlock", "error", "barriers whose robots wait for each other", _deadlocks),
    CheckRule("barrier.orphaned", "error", "a barrier a partner already went through", _orphans),
    CheckRule("energy.empty", "error", "battery below the reserve before a recharge", _empty),
    CheckRule("energy.margin", "warning", "battery below the safety margin", _margin),
    CheckRule(
        "coverage.needs_comms",
        "error",
        "a skill needing the link planned out of comms coverage",
        _needs_comms,
        needs_site=True,
    ),
    CheckRule(
        "coverage.barrier",
        "error",
        "a barrier a robot would wait at out of comms coverage: the partners never meet",
        _barrier_out,
        needs_site=True,
    ),
    CheckRule(
        "coverage.partner",
        "warning",
        "a skill working with a partner robot planned where they cannot talk",
        _partner_out,
        needs_site=True,
    ),
    CheckRule(
        "coverage.stranded",
        "warning",
        "a plan ending out of comms coverage",
        _stranded,
        needs_site=True,
    ),
    CheckRule(
        "coverage.cut_off",
        "warning",
        "the synchronized part ends out of coverage, more is planned after it",
        _cut_off,
        needs_site=True,
    ),
    CheckRule(
        "terrain.impassable", "error", "a goal on impassable ground", _impassable, needs_site=True
    ),
    CheckRule("terrain.no_route", "error", "no route to a goal", _no_route, needs_site=True),
    CheckRule(
        "terrain.unexplored", "warning", "a goal on unexplored ground", _unexplored, needs_site=True
    ),
    CheckRule(
        "marker.chosen_on_board",
        "warning",
        "a skill bound to a place chosen on board: the ground only estimates it",
        _estimated,
    ),
    CheckRule(
        "params.self_reference", "error", "a robot parameter naming its own robot", _self_reference
    ),
    CheckRule(
        "params.partner_apart",
        "warning",
        "a partner robot that is not in the skill's barrier",
        _partner_apart,
    ),
    CheckRule("params.flat_area", "error", "an area with no surface", _flat_area),
    CheckRule("params.crossed_area", "warning", "an area whose edges cross", _crossed_area),
    CheckRule(
        "params.useless_charge", "warning", "a recharge that will not charge", _useless_charge
    ),
    CheckRule(
        "contingency.timeout_short",
        "warning",
        "a timeout shorter than the skill's forecast duration",
        timeout_short,
    ),
    CheckRule(
        "contingency.branch_energy",
        "warning",
        "a fallback or goto that would run the battery below the reserve (worst case)",
        branch_energy,
    ),
    CheckRule(
        "contingency.after_deadlock",
        "error",
        "skills waiting (after) for skills that can only start after them",
        after_deadlock,
    ),
    CheckRule(
        "contingency.goto_impassable",
        "error",
        "a goto (rally point) on impassable ground",
        goto_impassable,
        needs_site=True,
    ),
)
RULE_NAMES = frozenset(r.rule for r in RULES)


def _courses(
    mission: Mission, library: Library, inputs: PlanInputs, robots: Collection[str] | None
) -> dict[str, Course]:
    legs = LegCache()
    out = {}
    for robot, spec in mission.robots.items():
        if robots is None or robot in robots:
            task = mission.tasks.get(robot, [])
            out[robot] = walk(library, robot, spec.type, task, inputs, legs, mission.markers)
    return out


def run_checks(
    mission: Mission,
    library: Library,
    inputs: PlanInputs,
    *,
    forecast: Forecast | None = None,
    robots: Collection[str] | None = None,
) -> list[Finding]:
    """Every finding, with its waiver; errors first. With a forecast, its
    courses are used (a console keeps one); `robots` limits the per-robot
    rules (barrier rules see every robot)."""
    ctx = _context(mission, library, inputs, forecast, robots)
    out: list[Finding] = []
    for rule in RULES:
        if rule.needs_site and inputs.site is None:
            continue
        for hit in rule.find(ctx):
            fid = f"{rule.rule}:{hit.subject}"
            out.append(
                Finding(
                    fid,
                    rule.rule,
                    rule.severity,
                    hit.message,
                    hit.robot,
                    hit.skills,
                    mission.waivers.get(fid),
                )
            )
    out.sort(key=lambda f: (f.severity != "error", f.id))
    return out


def _context(
    mission: Mission,
    library: Library,
    inputs: PlanInputs,
    forecast: Forecast | None,
    robots: Collection[str] | None,
) -> CheckContext:
    """What the rules look at: the forecast's courses (else walked now) of
    `robots` (None: all), and the barriers of every robot."""
    if forecast is not None:
        courses: Mapping[str, Course] = forecast.courses
        barriers = forecast.barriers
    else:
        courses = _courses(mission, library, inputs, robots)
        barriers = analyse(mission)
    if robots is not None:
        courses = {r: c for r, c in courses.items() if r in robots}
    return CheckContext(mission, library, inputs, courses, barriers)


def unfinished(mission: Mission) -> dict[str, list[SkillInstance]]:
    return {r: [s for s in t if s.status not in FINISHED] for r, t in mission.tasks.items()}
