"""The fleet screen's team actions (issue 30): add a robot that asks to
join, retire one (asking why: it is journaled)."""

from __future__ import annotations

from typing import Any

from backend.core.model import Status
from backend.core.ops import AddRobot, RetireRobot
from console.screens.checks import ReasonPrompt
from console.state.team import joining, retired


async def add_robot(screen: Any, robot: str | None, say: Any) -> None:
    """Add the selected robot if it asks to join (else the only one that does)."""
    model = screen.model
    asking = joining(model)
    if robot not in asking:
        if len(asking) != 1:
            say("select a robot that asks to join (✚) to add it", "warning")
            return
        robot = asking[0]
    assert robot is not None
    info = model.robots[robot]
    rtype = info.manifest.type if info.manifest is not None else ""
    await screen.ops.submit(AddRobot(name=robot, type=rtype), f"add robot {robot}", say=say)


def _why_not_retire(model: Any, robot: str | None) -> str | None:
    if robot is None or model.mission is None or robot not in model.mission.robots:
        return "select a robot of the mission to retire it"
    if retired(model, robot):
        return f"{robot} is retired already ({retired(model, robot)})"
    return None


def _retiring(model: Any, robot: str) -> str:
    """What retiring `robot` does, in the prompt."""
    plan = [s.id for s in model.task(robot) if s.status in (Status.IDLE, Status.IDLE_SYNCHRONIZED)]
    return (
        f"{robot} gets no new syncs; its queued skills are taken back (by its uplink, or on "
        f"the ground while it is out of reach); its plan ({len(plan)} skills) awaits "
        "reassignment (give to… on the schedule); its log stays"
    )


async def retire_robot(screen: Any, robot: str | None, say: Any) -> None:
    why = _why_not_retire(screen.model, robot)
    if why is not None or robot is None:
        say(why, "warning")
        return
    what = _retiring(screen.model, robot)
    prompt = ReasonPrompt(f"Retire {robot}", what, "why (e.g. stopped responding)", "retire")
    reason = await screen.app.push_screen_wait(prompt)
    if reason is None:
        say(f"{robot} kept in service")
        return
    op = RetireRobot(name=robot, reason=reason[:500])
    # its notes (always some: what happened to its queue) are the one notification
    await screen.ops.submit(op, f"retire {robot}", robot=robot, say=say, done="")
