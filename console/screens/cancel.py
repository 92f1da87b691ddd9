"""Cancelling a pending command from the console (the schedule, the fleet, the palette).

A confirmation names the command and what cancelling does now (withdrawn at
once while it has not left; asked of the robot once sent), then the server's
Cancel operation; the robot's later answer settles a sent one.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from backend.core.model import UplinkCommand
from backend.core.ops import Cancel
from console.operations import OperationService
from console.screens.dialogs import ConfirmScreen
from console.state import link


def toast_say(app: Any, title: str = "Uplink") -> Callable[..., None]:
    """A status line for a screen without one: the outcome as a notification
    (the "… under way" line is left out: the answer is what it says)."""

    def say(text: str, severity: str = "info") -> None:
        if not text.startswith("… "):
            level = {"error": "error", "warning": "warning"}.get(severity, "information")
            app.notify(text, title=title, severity=level)

    return say


async def ask_and_cancel(
    node: Any, ops: OperationService, c: UplinkCommand, say: Callable[..., object]
) -> None:
    """In a worker of `node` (a screen with the model): ask, then submit the cancel."""
    question = link.cancel_question(c, node.model.clock)
    if not await node.app.push_screen_wait(ConfirmScreen(question, yes="Cancel it", no="Keep it")):
        say(f"{c.op} #{c.id} to {c.robot} kept")
        return
    what = f"cancel {c.op} #{c.id} to {c.robot}"
    outcome = await ops.submit(Cancel(command=c.id), what, robot=c.robot, say=say, done="")
    if outcome.reply is None:
        return  # refused or failed: said already
    value = outcome.reply.value if isinstance(outcome.reply.value, dict) else {}
    if value.get("state") == "cancelled":
        say(f"{c.op} #{c.id} to {c.robot} cancelled: it never left", "ok")
    else:
        say(f"asked {c.robot} to cancel {c.op} #{c.id}: its answer decides", "ok")
