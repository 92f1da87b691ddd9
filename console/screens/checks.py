"""The plan checks (F8): every finding of the plan's checks, errors first,
with its waiver; the selected one in full below. w waives it (asks for the
reason: journaled, in every console's log), u withdraws the waiver, enter
shows its skill in the schedule. An unwaived error keeps its skills from
being synchronized (the schedule's sync says so)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rich.text import Text
from textual import on, work
from textual.app import ComposeResult
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.signal import Signal
from textual.widgets import DataTable, Footer, Input, Label, Static

from backend.core.ops import Unwaive, Waive
from backend.core.plan.checks import Finding
from console.bindings import bind, bindings, key_names
from console.operations import OperationService
from console.screens.base import ViewScreen
from console.state.changes import StateChange, Topic
from console.state.model import ConsoleModel

TCSS = Path(__file__).with_name("checks.tcss")
MARKS = {"error": "✖", "warning": "⚠"}


def mark(f: Finding) -> tuple[str, str | None]:
    """A finding's glyph and the theme variable it is drawn in (None: dim)."""
    if f.waiver is not None:
        return "≈", None
    return MARKS[f.severity], f.severity


class ReasonPrompt(ModalScreen[str | None]):
    """Why (required: it goes into the journal and every log): a finding is
    waived, a robot retired (console/screens/team.py)."""

    BINDINGS = [bind("dialog.cancel", "cancel")]
    CSS_PATH = TCSS

    def __init__(self, title: str, message: str, placeholder: str, verb: str) -> None:
        super().__init__()
        self.title_text = title
        self.message = message
        self.placeholder = placeholder
        self.verb = verb

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(self.title_text, classes="title")
            yield Static(self.message, classes="message")
            yield Input(placeholder=self.placeholder, id="reason")
            hint = key_names(self).hint(("dialog.ok", self.verb), ("dialog.cancel", "cancel"))
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
        self.dismiss(reason)

    def action_cancel(self) -> None:
        self.dismiss(None)


class ChecksScreen(ViewScreen):
    SCOPE = "checks"
    COLUMNS = (("", "mark"), ("Check", "id"), ("Robot", "robot"), ("What", "message"))
    TOPICS = frozenset({Topic.FORECAST, Topic.FINDINGS})
    BINDINGS = [*ViewScreen.BINDINGS, *bindings("checks")]
    CSS_PATH = [ViewScreen.CSS_PATH, TCSS]

    def __init__(
        self, model: ConsoleModel, changes: Signal[StateChange], ops: OperationService
    ) -> None:
        super().__init__(changes)
        self.model = model
        self.ops = ops
        self.shown: list[Finding] = []

    def compose(self) -> ComposeResult:
        yield self.title_bar
        yield DataTable(id="checks", cursor_type="row", zebra_stripes=False)
        yield Static("", id="detail", classes="detail")
        hint = key_names(self).hint(
            ("checks.waive", "waive (with a reason)"),
            ("checks.unwaive", "withdraw"),
            ("checks.schedule", "its skill"),
            ("app.show_timeline", "timeline"),
            ("app.show_mission", "schedule"),
        )
        yield Static(hint, classes="hint")
        yield Footer()

    def _cells(self, f: Finding) -> list[Text]:
        glyph, var = mark(f)
        style = "" if f.waiver is not None else "bold"
        return [
            Text(glyph, style=f"bold {self.colour(var)}" if var else "dim"),
            Text(f.id, style=style),
            Text(f.robot or "", style=style),
            Text(f.message, style="dim" if f.waiver is not None else ""),
        ]

    def redraw(self) -> None:
        if not self.ready:
            return
        t = self.query_one(DataTable)
        keep = t.cursor_row
        self.shown = list(self.model.plan.findings)
        with self.app.batch_update():
            t.clear()
            for f in self.shown:
                t.add_row(*self._cells(f), key=f.id)
            if self.shown:
                t.move_cursor(row=min(keep, len(self.shown) - 1))
        self._title()
        self._detail()

    def _title(self) -> None:
        errors, warnings, waived = self.model.plan.counts()
        if not self.shown:
            what = "no findings: the plan passes every check"
        else:
            what = f"{errors} error(s), {warnings} warning(s), {waived} waived"
        site = "with the site map" if self.model.plan.mirror is not None else "no site map"
        self.set_title(("plan checks", "bold"), f"  {what}  ·  {site}")

    @property
    def selected(self) -> Finding | None:
        t = self.query_one(DataTable)
        if not self.shown or not 0 <= t.cursor_row < len(self.shown):
            return None
        return self.shown[t.cursor_row]

    def _detail(self) -> None:
        f = self.selected
        detail = self.query_one("#detail", Static)
        if f is None:
            detail.update("Nothing to show: every check passes.")
            return
        glyph, var = mark(f)
        text = Text.assemble(
            (f"{glyph} {f.severity} ", f"bold {self.colour(var)}" if var else "dim"),
            (f.id, "bold"),
            "\n",
            f.message,
        )
        if f.waiver is not None:
            text.append(f"\nwaived at revision {f.waiver.revision}: {f.waiver.reason}", "italic")
        elif f.severity == "error":
            text.append("\nnot waived: its skills cannot be synchronized", "bold")
        detail.update(text)

    @on(DataTable.RowHighlighted)
    def _highlighted(self) -> None:
        self._detail()

    # -- actions ------------------------------------------------------------------------------
    def action_checks_waive(self) -> None:
        f = self.selected
        if f is None:
            return
        if f.waiver is not None:
            self.app.notify(
                f"already waived: {f.waiver.reason}", title=f.id, severity="warning", timeout=4
            )
            return

        def done(reason: str | None) -> None:
            if reason:
                self.submit(
                    Waive(check=f.id, reason=reason),
                    f"waive {f.id}",
                    robot=f.robot,
                    skill=f.skills[0] if f.skills else None,
                )

        prompt = ReasonPrompt(
            f"Waive {f.id}", f.message, "why it may go up the link anyway", "waive"
        )
        self.app.push_screen(prompt, done)

    def action_checks_unwaive(self) -> None:
        f = self.selected
        if f is None or f.waiver is None:
            if f is not None:
                self.app.notify("this finding is not waived", title=f.id, timeout=4)
            return
        self.submit(Unwaive(check=f.id), f"withdraw the waiver of {f.id}")

    @work(group="ops", exit_on_error=False)
    async def submit(self, op: Any, what: str, **kw: Any) -> None:
        """Its outcome on the schedule's status line (this screen has none)."""
        await self.ops.submit(op, what, **kw)

    def on_data_table_row_selected(self, event: DataTable.RowSelected) -> None:
        event.stop()  # enter on the table (the DataTable binds enter itself)
        self.action_checks_schedule()

    def action_checks_schedule(self) -> None:
        f = self.selected
        if f is not None and f.skills:
            self.model.selection.skill = f.skills[0]
        self.app.switch_mode("mission")
