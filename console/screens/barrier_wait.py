"""How long a barrier's robots wait for each other, and then: the barrier
action with no skill marked, on a skill of a barrier (ctl: `barrier B
--barrier-timeout 10m --on-timeout continue`)."""

from __future__ import annotations

from textual import on
from textual.app import ComposeResult
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import Input, Select, Static

from backend.core.contingency import read_seconds, span_text
from backend.core.model import Barrier, BarrierTimeout
from console.bindings import bind, key_names
from console.widgets.select import SafeSelect

THEN = [
    ("then start alone (continue)", "continue"),
    ("then fail the skill (halt)", "halt"),
]


class BarrierWaitPrompt(ModalScreen[BarrierTimeout | None]):
    """A barrier's timeout (mission time; empty: for ever) and what follows it."""

    BINDINGS = [bind("dialog.cancel", "cancel")]
    AUTO_FOCUS = "#timeout"
    DEFAULT_CSS = """
    BarrierWaitPrompt { align: center middle; }
    BarrierWaitPrompt > Vertical {
        width: 64; max-width: 95%; height: auto;
        border: thick $primary; background: $surface; padding: 1 2;
    }
    BarrierWaitPrompt #timeout { margin: 1 0 0 0; }
    BarrierWaitPrompt .hint { color: $text-muted; }
    BarrierWaitPrompt .error { color: $error; }
    """

    def __init__(self, barrier: str, current: Barrier) -> None:
        super().__init__()
        self.barrier = barrier
        self.current = current

    def compose(self) -> ComposeResult:
        c = self.current
        with Vertical():
            yield Static(
                f"Barrier {self.barrier} ({', '.join(c.skills)}): how long does each robot "
                "wait for its partners? Mission time (10m, 1.5h); empty: for ever. Decided "
                "on board."
            )
            yield Input(
                span_text(c.timeout) if c.timeout is not None else "",
                id="timeout",
                placeholder="for ever",
            )
            yield SafeSelect(THEN, value=c.on_timeout, allow_blank=False, id="then")
            hint = key_names(self).hint(("dialog.ok", "set"), ("dialog.cancel", "cancel"))
            yield Static(hint, classes="hint")
            yield Static("", id="error", classes="error")

    @on(Input.Submitted)
    def _submitted(self, event: Input.Submitted) -> None:
        seconds = read_seconds(event.value)
        if isinstance(seconds, str):
            self.query_one("#error", Static).update(seconds)
            return
        then = str(self.query_one("#then", Select).value)
        self.dismiss(BarrierTimeout(timeout=seconds, on_timeout=then))  # type: ignore[arg-type]

    def action_cancel(self) -> None:
        self.dismiss(None)
