"""The mission screen's execution actions: synchronize and unsynchronize a
robot's plan, retry a failed skill, run / pause / stop / reset one robot or
all of them (an object the screen owns; its keys call these)."""

from __future__ import annotations

from typing import Any

from backend.core.ops import Control, Retry, Sync, Unsync
from backend.core.plan.at_sync import at_sync
from console.screens.dialogs import ConfirmScreen


class RunActions:
    def __init__(self, screen: Any) -> None:
        self.screen = screen  # MissionScreen: selection, say, submit, app

    def sync(self, undo: bool = False) -> None:
        """Synchronize the selected robot through the selected skill (`undo`:
        unsynchronize it from there)."""
        s = self.screen
        robot, sid = s.selection()
        if robot is None or sid is None:
            return
        if undo:
            op: Unsync | Sync = Unsync(robot=robot, from_id=sid)
        else:  # with the plan's forecast of what it sends: the review's plan against actual
            plan = s.model.plan
            forecast = at_sync(plan.forecast, s.model.task(robot), sid)
            op = Sync(robot=robot, through=sid, forecast=forecast)
        what = "unsync" if undo else "sync"

        def done(r: Any) -> None:
            if not undo:  # this console's own syncs: the timeline draws them as planned
                s.model.plan.planned.update(
                    {k: (p.start.timestamp(), p.end.timestamp()) for k, p in op.forecast.items()}
                )
            s.say(_queued(robot, what, r.value), "ok")

        s.submit(
            op,
            f"{what} {robot} {'from' if undo else 'through'} {sid}",
            robot=robot,
            skill=sid,
            then=done,
        )

    def retry(self) -> None:
        s = self.screen
        robot, sid = s.selection()
        if sid is None:
            return
        s.submit(
            Retry(id=sid),
            f"retry {sid}",
            robot=robot,
            skill=sid,
            then=lambda r: s.say(
                f"{robot}: {r.value.get('id', '')} queued right after {sid} (run to start it)", "ok"
            ),
        )

    def control(self, op: str, robot: str | None) -> None:
        s = self.screen
        who = robot or "all robots"

        def ok(r: Any) -> None:
            notes = "; ".join(r.notes)
            commands = r.value.get("commands", {}) if isinstance(r.value, dict) else {}
            # the robot's answer comes later (its skills then change): say what waits for it
            queued = ", ".join(f"{rb} (command {c})" for rb, c in commands.items())
            done = f"queued for {queued}" if queued else "ok"
            s.say(
                f"{op} {who}: {done}" + (f" — {notes}" if notes else ""),
                "warning" if notes else "ok",
            )  # the notes' notification is the operation service's (one, not two)

        s.submit(Control(op=op, robot=robot), f"{op} {who}", robot=robot, then=ok)

    async def reset(self, robot: str | None) -> None:
        """Asked first: everything queued returns to the plan."""
        question = (
            f"Reset {robot}? Its active skill stops and everything queued returns to the plan."
            if robot
            else "Reset ALL robots? Active skills stop and everything queued returns to the plan."
        )
        yes = "Reset" if robot else "Reset all"
        if await self.screen.app.push_screen_wait(ConfirmScreen(question, yes=yes)):
            self.control("reset", robot)


def _queued(robot: str, what: str, value: dict[str, Any]) -> str:
    """Protocol 2: the operation returns once its command is queued for the
    robot; the skills change when the robot answers."""
    skills = ", ".join(value.get("skills", []))
    return f"{robot}: {what} queued (command {value.get('command')}): {skills}"
