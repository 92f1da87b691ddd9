""" "Give to…" (issue 30): the selected skill, the marked ones or a retired
robot's whole plan go to another robot, chosen from a list of the robots
in service ranked by the forecast (earliest end with them, then battery
left); a robot that cannot take them says why and cannot be chosen."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rich.text import Text
from textual import on, work
from textual.app import ComposeResult
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import Label, OptionList, Static
from textual.widgets.option_list import Option

from backend.core.plan.suggest import Suggestion
from console.bindings import bind, key_names
from console.state.clock import MissionClock
from console.state.team import Gift, gift, hint_words, ranked


class GiveToScreen(ModalScreen[str | None]):
    """The robots ranked for a gift; enter gives it to the highlighted one."""

    BINDINGS = [bind("dialog.cancel", "cancel")]
    CSS_PATH = Path(__file__).with_name("team.tcss")

    def __init__(self, words: str, hints: list[Suggestion], now: float, clock: MissionClock):
        super().__init__()
        self.words = words
        self.hints = hints
        self.now = now
        self.clock = clock

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(Text(f"Give {self.words} to…", style="bold"), classes="question")
            yield Static("ranked by the forecast: earliest end with them, then battery left")
            yield OptionList(*(self._option(n, h) for n, h in enumerate(self.hints)), id="robots")
            hint = key_names(self).hint(
                ("dialog.ok", "give"),
                (("dialog.previous", "dialog.next"), "move"),
                ("dialog.cancel", "cancel"),
            )
            yield Static(hint, classes="hint")

    def _option(self, n: int, h: Suggestion) -> Option:
        text = Text()
        text.append(f"{h.robot:<8}", style="bold" if h.moved else "dim")
        text.append(hint_words(h, self.now, self.clock), style="" if h.capable else "dim")
        if h.capable and n == 0:
            text.append("  ★ best", style="bold")
        return Option(text, id=h.robot, disabled=not h.moved)

    def on_mount(self) -> None:
        ol = self.query_one(OptionList)
        first = next((i for i, h in enumerate(self.hints) if h.moved), None)
        if first is not None:
            ol.highlighted = first
        ol.focus()

    @on(OptionList.OptionSelected)
    def _selected(self, event: OptionList.OptionSelected) -> None:
        self.dismiss(event.option.id)

    def action_cancel(self) -> None:
        self.dismiss(None)


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
    if not any(h.moved for h in hints):
        why = "; ".join(f"{h.robot}: {hint_words(h, 0, model.clock)}" for h in hints)
        screen.say(f"no robot can take {g.words}: {why or 'no other robot in service'}", "warning")
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
