"""The review's "go to" prompt: a time or a revision, as typed."""

from __future__ import annotations

from textual import on
from textual.app import ComposeResult
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import Input, Static

from console.bindings import bind
from console.state.replay import GOTO_HELP, parse_goto


class GotoScreen(ModalScreen[tuple[str, float] | None]):
    """Dismissed with ("time", t) or ("revision", n), or None (escape)."""

    BINDINGS = [bind("dialog.cancel", "cancel")]
    DEFAULT_CSS = """
    GotoScreen { align: center middle; }
    GotoScreen > Vertical {
        width: 72; max-width: 95%; height: auto;
        border: thick $primary; background: $surface; padding: 1 2;
    }
    GotoScreen .hint { color: $text-muted; }
    GotoScreen .error { color: $error; }
    """

    def __init__(self, now: float, clock: str) -> None:
        super().__init__()
        self.now = now
        self.clock = clock
        self._error = Static("", classes="error")

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Static(f"Go to ({self.clock})", classes="head")
            yield Static(GOTO_HELP, classes="hint")
            yield Input(placeholder="14:32", id="when")
            yield self._error

    def on_mount(self) -> None:
        self.query_one(Input).focus()

    @on(Input.Submitted)
    def _submitted(self, event: Input.Submitted) -> None:
        try:
            self.dismiss(parse_goto(event.value, self.now))
        except ValueError as e:
            self._error.update(str(e))

    def action_cancel(self) -> None:
        self.dismiss(None)
