"""Plan checks of contingencies (backend.core.plan.checks registers them):
a timeout the forecast says the skill cannot meet, and a goto whose rally
point a rover cannot reach."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from itertools import product
from typing import Any

from backend.core.contingency import TRIGGERS, span_text
from backend.core.model import FINISHED, Goto, SkillInstance
from backend.core.plan.course import Step
from backend.core.plan.geometry import Point, point_of
from backend.core.plan.hit import Hit
from backend.core.plan.order import strong_components

# `ctx` is the checks' CheckContext (mission, courses, site): typed loosely, as
# backend.core.plan.checks imports these rules
CheckContext = Any


def timeout_short(ctx: CheckContext) -> Iterator[Hit]:
    """A planned skill whose forecast duration exceeds its timeout: its
    on_timeout branch is the plan, not a contingency."""
    steps = [(robot, step) for robot, c in ctx.courses.items() for step in c.steps]
    for robot, step in steps:
        timeout = step.skill.policies.timeout or float("inf")
        takes = step.assumed.skill_s if step.assumed is not None else step.busy_s
        if step.remaining == 1 and takes > timeout:  # not started, and too long
            yield Hit(
                f"{step.skill.id}/timeout",
                f"{robot}: {step.skill.display()} takes about {span_text(round(takes))} "
                f"by the forecast, longer than its timeout {span_text(timeout)}: it would "
                f"end by its on_timeout (the forecast counts that); give it more time",
                robot=robot,
                skills=(step.skill.id,),
            )


def branch_energy(ctx: CheckContext) -> Iterator[Hit]:
    """A branch that would run the battery below the reserve (the worst path:
    from the skill's end, or its timeout if sooner, then the branch's skills)."""
    for robot, step, b, reserve in _short_branches(ctx):
        when = "fails at its end" if b.trigger == "failure" else "times out"
        yield Hit(
            f"{step.skill.id}/on_{b.trigger}",
            f"{robot}: if {step.skill.display()} {when}, its {b.text} would take the battery "
            f"to {max(0.0, b.battery_min or 0.0) * 100:.0f}%, below the reserve "
            f"{reserve * 100:.0f}% it stops at: the branch could not finish; recharge "
            "before the skill, or choose a nearer branch",
            robot=robot,
            skills=(step.skill.id,),
        )


def _short_branches(ctx: CheckContext) -> Iterator[tuple[str, Step, Any, float]]:
    """(robot, step, its worst branch, the reserve) where that branch goes below it."""
    for robot, c in ctx.courses.items():
        reserve = c.battery.reserve if c.battery is not None else -1.0
        for step in c.steps:
            low = step.worst.battery_min if step.worst is not None else None
            if low is not None and low < reserve:
                yield robot, step, step.worst, reserve


def goto_impassable(ctx: CheckContext) -> Iterator[Hit]:
    """A goto to a marker on impassable ground (rovers: a drone flies over)."""
    site = ctx.site
    for robot, step, trigger, name, at in _rally_points(ctx):
        if site is not None and site.passable(*at) is False:
            yield Hit(
                f"{step.skill.id}/{trigger}",
                f"{robot}: {step.skill.display()}'s {trigger} goes to marker {name}, on "
                "impassable ground; choose another rally point",
                robot=robot,
                skills=(step.skill.id,),
            )


def _rally_points(ctx: CheckContext) -> Iterator[tuple[str, Step, str, str, Point]]:
    """(robot, step, trigger, marker, where) of every goto of a rover's plan."""
    steps = [(r, step) for r, c in ctx.courses.items() if _drives(c) for step in c.steps]
    for (robot, step), trigger in product(steps, TRIGGERS):
        branch = getattr(step.skill.policies, trigger)
        at = _marker_point(ctx, branch.goto) if isinstance(branch, Goto) else None
        if at is not None:
            yield robot, step, trigger, branch.goto, at


def _drives(course: Any) -> bool:
    return course.robot_type is not None and not course.robot_type.flies


def _marker_point(ctx: CheckContext, name: str) -> Point | None:
    marker = ctx.mission.markers.get(name)
    return point_of(marker.model_dump().get("pose")) if marker is not None else None


def after_deadlock(ctx: CheckContext) -> Iterator[Hit]:
    """Skills that wait for each other through `after` (with each robot's
    order and its barriers): none of them can ever start."""
    tasks = [[s for s in t if s.status not in FINISHED] for t in ctx.mission.tasks.values()]
    waits = _waits(tasks)
    node = _barrier_nodes(ctx.mission)
    graph = _start_order(tasks, node)  # a skill (or barrier) -> what must start before it
    for sid, after in waits.items():
        graph.setdefault(node(sid), set()).add(node(after))
    for ring in _rings(graph, waits, node):
        yield Hit(
            "+".join(ring),
            f"{', '.join(ring)} wait (after) for skills that can only start after them; "
            "reorder these skills or drop an after",
            skills=tuple(ring),
        )


def _rings(
    graph: dict[str, set[str]], waits: dict[str, str], node: Callable[[str], str]
) -> Iterator[list[str]]:
    """The waiting skills of each cycle of `graph` that has some, sorted."""
    for comp in strong_components(graph):
        ring = sorted(sid for sid in waits if node(sid) in comp)
        if ring:
            yield ring


def _waits(tasks: list[list[SkillInstance]]) -> dict[str, str]:
    """Unfinished skill -> the unfinished skill it waits for (a finished one holds nobody)."""
    ids = {s.id for t in tasks for s in t}
    return {s.id: str(s.policies.after) for t in tasks for s in t if s.policies.after in ids}


def _start_order(
    tasks: list[list[SkillInstance]], node: Callable[[str], str]
) -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for task in tasks:
        for before, later in zip(task, task[1:], strict=False):
            graph.setdefault(node(later.id), set()).add(node(before.id))
    return graph


def _barrier_nodes(m: Any) -> Callable[[str], str]:
    """A skill's node: the members of a barrier start together, as one."""
    of = {sid: f"barrier {bid}" for bid, b in m.barriers.items() for sid in b.skills}
    return lambda sid: of.get(sid, sid)
