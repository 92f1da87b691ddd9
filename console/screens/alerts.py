"""The alert list: newest first, unacknowledged ones marked ● and bold;
enter/a acknowledges the selected alert, A all of them; the selected
alert's whole text below the list (a row is cut at 80 columns). The count
of unacknowledged alerts is the badge on the mission screen's top bar."""

from __future__ import annotations

from rich.text import Text
from textual.app import ComposeResult
from textual.signal import Signal
from textual.widgets import DataTable, Footer, Static

from console.bindings import bindings, key_names
from console.messages import AlertAcknowledged, QuestionRequested
from console.screens.base import ViewScreen
from console.state.changes import StateChange, Topic
from console.state.clock import MissionClock
from console.state.eventlog import AlertBook, AlertEntry

LEVEL_VARS = {"error": "error", "warning": "warning", "info": "primary"}
KIND_WORDS = {
    "failure": "failure",
    "offline": "offline",
    "out_of_range": "out of range",
    "low_battery": "low battery",
    "refusal": "refusal",
    "malformed": "unreadable message",
    "report_refused": "report refused",
    "robot_error": "robot error",
    "question": "question",
}


class AlertScreen(ViewScreen):
    SCOPE = "alerts"
    COLUMNS = (
        ("", "ack"),
        ("Time", "at"),
        ("Kind", "kind"),
        ("Robot", "robot"),
        ("What", "message"),
        ("Level", "level"),
        ("From", "source"),
    )
    TOPICS = frozenset({Topic.ALERTS})
    BINDINGS = [*ViewScreen.BINDINGS, *bindings("alerts")]

    def __init__(
        self,
        book: AlertBook,
        changes: Signal[StateChange],
        clock: MissionClock | None = None,
    ) -> None:
        super().__init__(changes)
        self.book = book
        self.clock = clock or MissionClock()  # alerts' times are said in mission time
        self.ids: list[int] = []

    def compose(self) -> ComposeResult:
        yield self.title_bar
        yield DataTable(id="alerts", cursor_type="row")
        yield Static("", id="alert-detail", classes="detail")
        hint = key_names(self).hint(
            ("alerts.ack", "acknowledge"),
            ("alerts.ack_all", "acknowledge all"),
            ("alerts.answer", "answer"),
            ("app.show_mission", "schedule"),
            ("app.show_log", "event log"),
        )
        yield Static(hint, classes="hint")
        yield Footer()

    def _cells(self, a: AlertEntry) -> list:
        style = "" if a.acknowledged else "bold"
        level = Text(a.level, style=f"{style} {self.colour(LEVEL_VARS[a.level])}".strip())
        count = f" (×{a.count})" if a.count > 1 else ""
        return [
            self._mark(a),
            Text(self.clock.stamp_text(a.at)),
            Text(KIND_WORDS.get(a.kind, a.kind)),
            Text(a.robot or ""),
            Text(a.message + count, style=style or "dim"),
            level,
            Text(a.source),
        ]

    def _mark(self, a: AlertEntry) -> Text:
        """✓ acknowledged, ● not yet."""
        if a.acknowledged:
            return Text("✓", style="dim")
        return Text("●", style=f"bold {self.colour('warning')}")

    def redraw(self) -> None:
        if not self.ready:
            return
        t = self.query_one(DataTable)
        keep = t.cursor_row
        alerts = list(reversed(self.book.alerts))
        self.ids = [a.id for a in alerts]
        with self.app.batch_update():
            t.clear()
            for a in alerts:
                t.add_row(*self._cells(a), key=str(a.id))
            if alerts:
                t.move_cursor(row=min(keep, len(alerts) - 1))
        self._detail()
        n = self.book.unacknowledged
        self.set_title(
            ("Alerts", "bold"), f"  {n} unacknowledged of {len(alerts)}" if alerts else "  none"
        )

    def _detail(self) -> None:
        """The selected alert in full: when, what, about whom, from where."""
        box = self.query_one("#alert-detail", Static)
        selected = self._selected_id()
        a = next((x for x in self.book.alerts if x.id == selected), None)
        if a is None:
            box.update("")
            return
        box.update(Text.assemble(self._head(a), "\n", a.message))

    def _head(self, a: AlertEntry) -> Text:
        """When, what kind, about whom; its level, source and count dim."""
        about = " · ".join(x for x in (a.robot, a.skill) if x)
        return Text.assemble(
            (f"{self.clock.stamp_text(a.at)}  {KIND_WORDS.get(a.kind, a.kind)}", "bold"),
            f"  {about}" if about else "",
            (f"  {a.level} · from {a.source}" + (f" · ×{a.count}" if a.count > 1 else ""), "dim"),
        )

    def _selected_id(self) -> int | None:
        """The id of the alert under the cursor (None: no alert there)."""
        row = self.query_one(DataTable).cursor_row
        return self.ids[row] if self.ids and row < len(self.ids) else None

    def on_data_table_row_highlighted(self, event: DataTable.RowHighlighted) -> None:
        self._detail()

    def action_ack(self) -> None:
        selected = self._selected_id()
        if selected is not None:
            self.post_message(AlertAcknowledged(selected))

    def action_answer(self) -> None:
        """The selected alert's question (another alert: the oldest open question)."""
        t = self.query_one(DataTable)
        by_id = {a.id: a for a in self.book.alerts}
        a = by_id.get(self.ids[t.cursor_row]) if self.ids and t.cursor_row < len(self.ids) else None
        self.post_message(QuestionRequested(a.question if a is not None else None))

    def action_ack_all(self) -> None:
        self.post_message(AlertAcknowledged(None))

    def on_data_table_row_selected(self, event: DataTable.RowSelected) -> None:
        # enter on the table (the DataTable binds enter itself)
        event.stop()
        self.action_ack()
