""" "Give to…" (issue 30): the selected skill, the marked ones or a retired
robot's whole plan go to another robot, chosen from a list of the robots
in service ranked by the forecast (the most of them taken, the earliest end
with them, then the least time out of comms coverage, then battery left); a
robot that cannot take them says why and cannot be chosen."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.containers import Vertical
from textual.widgets import Label, OptionList, Static
from textual.widgets.option_list import Option

from backend.core.plan.suggest import Suggestion
from console.bindings import key_names
from console.screens.dialogs import TCSS, ChoiceScreen
from console.state.clock import MissionClock
from console.state.team import Gift, gift, hint_words, nobody_takes, ranked

RANKED = "ranked: most taken, soonest end, least out of coverage, most battery"


class GiveToScreen(ChoiceScreen):
    """The robots ranked for a gift; enter gives it to the highlighted one (a
    robot that can take none of it cannot be chosen: it says why)."""

    CSS_PATH = [TCSS, Path(__file__).with_name("team.tcss")]

    def __init__(self, words: str, hints: list[Suggestion], now: float, clock: MissionClock):
        rows = [(h.robot, _row(n, h, now, clock)) for n, h in enumerate(hints)]
        first = next((i for i, h in enumerate(hints) if h.moved), 0)
        super().__init__(f"Give {words} to…", rows, highlighted=first)
        self.takers = {h.robot for h in hints if h.moved}

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(Text(self.question, style="bold"), classes="question")
            yield Static(RANKED)
            options = (Option(p, id=r, disabled=r not in self.takers) for r, p in self.rows)
            yield OptionList(*options, id="choices")
            hint = key_names(self).hint(
                ("dialog.ok", "give"),
                (("dialog.previous", "dialog.next"), "move"),
                ("dialog.cancel", "cancel"),
            )
            yield Static(hint, classes="hint")


def _row(n: int, h: Suggestion, now: float, clock: MissionClock) -> Text:
    text = Text()
    text.append(f"{h.robot:<8}", style="bold" if h.moved else "dim")
    text.append(hint_words(h, now, clock), style="" if h.capable else "dim")
    if h.moved and n == 0:  # the ranking's first: it takes the most, soonest
        text.append("  ★ best", style="bold")
    return text


@work(group="dialog")
async def give_action(screen: Any) -> None:
    """The mission screen's `action_give_to` (a worker: it waits for the dialog)."""
    await give(screen)


async def give(screen: Any) -> None:
    """From the mission screen (in a worker): choose the robot, submit the reassign."""
    model = screen.model
    robot, sid = screen.selection()
    try:
        g = gift(model, robot, sid, list(screen.schedule.marks))
    except ValueError as e:
        screen.say(str(e), "warning")
        return
    hints = ranked(model, g)
    nobody = nobody_takes(g, hints, model.clock)
    if nobody is not None:
        screen.say(nobody, "warning")
        return
    now = model.clock().timestamp()
    chosen = await screen.app.push_screen_wait(GiveToScreen(g.words, hints, now, model.clock))
    if chosen is None:
        screen.say("give cancelled")
        return
    _submit(screen, g, chosen)


def _submit(screen: Any, g: Gift, to: str) -> None:
    def given(reply: Any) -> None:
        moved = reply.value.get("moved", [])
        stays = reply.value.get("refused", {})
        screen.schedule.clear_marks()
        screen.update_top()
        rest = f"; {len(stays)} stay (see the notes)" if stays else ""
        screen.say(f"gave {', '.join(moved)} to {to}{rest}", "ok")
        if moved:
            screen.plan.select_new(moved[0], edit=False)

    screen.submit(g.op(to), f"give {g.words} to {to}", robot=to, then=given)
