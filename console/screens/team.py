"""The fleet screen's team actions (issue 30): add a robot that asks to
join, retire one (asking why: it is journaled)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from textual import on
from textual.app import ComposeResult
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import Input, Label, Static

from backend.core.model import Status
from backend.core.ops import AddRobot, RetireRobot
from console.bindings import bind, key_names
from console.state.team import joining, retired


class RetirePrompt(ModalScreen[str | None]):
    """Why a robot is retired (required: it goes into the journal and every log)."""

    BINDINGS = [bind("dialog.cancel", "cancel")]
    CSS_PATH = Path(__file__).with_name("team.tcss")

    def __init__(self, robot: str, what: str) -> None:
        super().__init__()
        self.robot = robot
        self.what = what

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(f"Retire {self.robot}", classes="title")
            yield Static(self.what, classes="message")
            yield Input(placeholder="why (e.g. stopped responding)", id="reason")
            hint = key_names(self).hint(("dialog.ok", "retire"), ("dialog.cancel", "cancel"))
            yield Static(hint, classes="hint")
            yield Static("", id="error", classes="error")

    def on_mount(self) -> None:
        self.query_one(Input).focus()

    @on(Input.Submitted)
    def _submitted(self, event: Input.Submitted) -> None:
        reason = event.value.strip()
        if not reason:
            self.query_one("#error", Static).update("give a reason: it is journaled")
            return
        self.dismiss(reason[:500])

    def action_cancel(self) -> None:
        self.dismiss(None)


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


async def retire_robot(screen: Any, robot: str | None, say: Any) -> None:
    model = screen.model
    if robot is None or model.mission is None or robot not in model.mission.robots:
        say("select a robot of the mission to retire it", "warning")
        return
    if retired(model, robot):
        say(f"{robot} is retired already ({retired(model, robot)})", "warning")
        return
    plan = [s.id for s in model.task(robot) if s.status in (Status.IDLE, Status.IDLE_SYNCHRONIZED)]
    what = (
        f"{robot} gets no new syncs; its queued skills are taken back (by its uplink, or on "
        f"the ground while it is out of reach); its plan ({len(plan)} skills) awaits "
        "reassignment (give to… on the schedule); its log stays"
    )
    reason = await screen.app.push_screen_wait(RetirePrompt(robot, what))
    if reason is None:
        say(f"{robot} kept in service")
        return
    op = RetireRobot(name=robot, reason=reason)
    await screen.ops.submit(op, f"retire {robot}", robot=robot, say=say)
