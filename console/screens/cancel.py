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
from console.messages import OperationRequested
from console.screens.dialogs import ConfirmScreen
from console.state import link


def _done(c: UplinkCommand, say: Callable[..., object]) -> Callable[[Any], None]:
    def ok(reply: Any) -> None:
        value = reply.value if isinstance(reply.value, dict) else {}
        if value.get("state") == "cancelled":
            say(f"{c.op} #{c.id} to {c.robot} cancelled: it never left", "ok")
        else:
            say(f"asked {c.robot} to cancel {c.op} #{c.id}: its answer decides", "ok")

    return ok


async def ask_and_cancel(node: Any, c: UplinkCommand, say: Callable[..., object]) -> None:
    """In a worker of `node` (a screen with the model): ask, then submit the cancel."""
    question = link.cancel_question(c, node.model.clock)
    if await node.app.push_screen_wait(ConfirmScreen(question, yes="Cancel it", no="Keep it")):
        node.post_message(
            OperationRequested(
                Cancel(command=c.id),
                f"cancel {c.op} #{c.id} to {c.robot}",
                robot=c.robot,
                on_ok=_done(c, say),
                say=say,
            )
        )
    else:
        say(f"{c.op} #{c.id} to {c.robot} kept")
