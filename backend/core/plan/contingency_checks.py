"""Plan checks of contingencies (backend.core.plan.checks registers them):
a timeout the forecast says the skill cannot meet, and a goto whose rally
point a rover cannot reach."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from backend.core.contingency import TRIGGERS, span_text
from backend.core.model import Goto
from backend.core.plan.course import Step
from backend.core.plan.geometry import Point, point_of
from backend.core.plan.hit import Hit

# `ctx` is the checks' CheckContext (mission, courses, site): typed loosely, as
# backend.core.plan.checks imports these rules
CheckContext = Any


def timeout_short(ctx: CheckContext) -> Iterator[Hit]:
    """A planned skill whose forecast duration exceeds its timeout: its
    on_timeout branch is the plan, not a contingency."""
    steps = [(robot, step) for robot, c in ctx.courses.items() for step in c.steps]
    for robot, step in steps:
        timeout = step.skill.policies.timeout or float("inf")
        if step.remaining == 1 and step.busy_s > timeout:  # not started, and too long
            yield Hit(
                f"{step.skill.id}/timeout",
                f"{robot}: {step.skill.display()} takes about {span_text(round(step.busy_s))} "
                f"by the forecast, longer than its timeout {span_text(timeout)}: it would "
                f"end by its on_timeout; give it more time",
                robot=robot,
                skills=(step.skill.id,),
            )


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
    rovers = {r: c for r, c in ctx.courses.items() if c.robot_type and not c.robot_type.flies}
    for robot, course in rovers.items():
        for step in course.steps:
            for trigger in TRIGGERS:
                branch = getattr(step.skill.policies, trigger)
                at = _marker_point(ctx, branch.goto) if isinstance(branch, Goto) else None
                if at is not None:
                    yield robot, step, trigger, branch.goto, at


def _marker_point(ctx: CheckContext, name: str) -> Point | None:
    marker = ctx.mission.markers.get(name)
    return point_of(marker.model_dump().get("pose")) if marker is not None else None
