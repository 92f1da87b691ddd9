"""The event log screen: every operation (which console and user), robot
report, refusal, failure and alert, newest last; filter by robot, kind and
text; export what is shown to a JSON-lines file (ctrl+s). The console keeps
the last `LOG_LIMIT` entries in memory."""

from __future__ import annotations

from itertools import takewhile
from pathlib import Path

from rich.text import Text
from textual import on, work
from textual.app import ComposeResult
from textual.signal import Signal
from textual.widgets import DataTable, Footer, Input, Static

from console.bindings import bindings, key_names
from console.screens.base import ViewScreen
from console.screens.dialogs import PathPrompt
from console.state.changes import StateChange, Topic
from console.state.clock import MissionClock
from console.state.eventlog import LOG_LIMIT, EventLog, LogEntry, entry_matches
from console.state.files import shown_path

# rows in the table (a DataTable of 10k rows takes seconds to fill); export writes all matches
SHOW_LIMIT = 1_000

KIND_VARS = {
    "failure": "status-failure",
    "refusal": "error",
    "alert": "warning",
    "report": "status-running",
    "operation": "secondary",
}


class EventLogScreen(ViewScreen):
    SCOPE = "log"
    COLUMNS = (
        ("Time", "at"),
        ("Kind", "kind"),
        ("Robot", "robot"),
        ("What", "text"),
        ("Who", "who"),
    )
    TOPICS = frozenset({Topic.LOG})
    BINDINGS = [*ViewScreen.BINDINGS, *bindings("log")]

    def __init__(
        self,
        log: EventLog,
        changes: Signal[StateChange],
        clock: MissionClock | None = None,
    ) -> None:
        super().__init__(changes)
        self.log_ = log
        self.clock = clock or MissionClock()  # entries' times are said in mission time
        self.last_seq = 0  # newest entry in the table
        self.rows: list[int] = []  # seqs shown, oldest first
        self.matching = 0  # entries matching the filter (the table shows the last SHOW_LIMIT)

    def compose(self) -> ComposeResult:
        yield self.title_bar
        yield Input(
            placeholder=(
                "filter: robot:lru1 kind:failure words…  "
                "(kinds: operation report refusal failure alert)"
            ),
            id="filter",
        )
        yield DataTable(id="log", cursor_type="row")
        # the selected entry in full (the table cuts at 80 columns)
        yield Static("", id="entry", classes="detail")
        hint = key_names(self).hint(
            ("log.export", "export shown entries (JSON lines)"), ("app.show_mission", "schedule")
        )
        yield Static(f"last {LOG_LIMIT:,} entries kept in memory · {hint}", classes="hint")
        yield Footer()

    def shown_entries(self) -> list[LogEntry]:
        return self.log_.select(self.query_text)

    def _cells(self, e: LogEntry) -> list:
        who = f"{e.user}@{e.client}" if e.user else e.client
        colour = self.colour(KIND_VARS.get(e.kind, ""), "")
        # Text, not str: a str cell is parsed as markup ("[lru1] …" would vanish)
        return [
            Text(self.clock.stamp_text(e.at)),
            Text(e.kind, style=colour),
            Text(", ".join(e.robots)),
            Text(e.text),
            Text(who),
        ]

    def _add(self, t: DataTable, entries: list[LogEntry]) -> None:
        for e in entries:
            t.add_row(*self._cells(e), key=str(e.seq))
            self.rows.append(e.seq)
        if entries:
            self.last_seq = entries[-1].seq

    def redraw(self) -> None:
        if not self.ready:
            return
        t = self.query_one(DataTable)
        with self.app.batch_update():
            t.clear()
            self.rows = []
            self.last_seq = self.log_.seq
            matching = self.shown_entries()
            self.matching = len(matching)
            self._add(t, matching[-SHOW_LIMIT:])
            t.move_cursor(row=max(0, t.row_count - 1))
        self._title()
        self._show_entry()

    def update_view(self, change: StateChange) -> None:
        """New entries: append (and drop rows the bounded log forgot)."""
        t = self.query_one(DataTable)
        at_end = t.cursor_row >= t.row_count - 1
        entries = self.log_.entries
        # the new ones are at the end: walk back only over them
        new = list(takewhile(lambda e: e.seq > self.last_seq, reversed(entries)))[::-1]
        self.last_seq = self.log_.seq
        with self.app.batch_update():
            self._drop_rows_before(t, entries[0].seq if entries else 0)
            added = [e for e in new if entry_matches(e, self.query_text)]
            self._count_matching(added, evicting=len(entries) == entries.maxlen)
            self._add(t, added)
            while len(self.rows) > SHOW_LIMIT:
                t.remove_row(str(self.rows.pop(0)))
            if at_end:
                t.move_cursor(row=max(0, t.row_count - 1))
        self._title()

    def _drop_rows_before(self, t: DataTable, oldest: int) -> None:
        """The rows of entries the bounded log forgot."""
        while self.rows and self.rows[0] < oldest:
            t.remove_row(str(self.rows.pop(0)))

    def _count_matching(self, added: list[LogEntry], *, evicting: bool) -> None:
        entries = self.log_.entries
        if not self.query_text:
            self.matching = len(entries)
        elif evicting:  # forgotten entries may have matched: count again
            self.matching = sum(1 for e in entries if entry_matches(e, self.query_text))
        else:
            self.matching += len(added)

    def _title(self) -> None:
        n = len(self.log_.entries)
        shown = f" · {self.matching} match '{self.query_text}'" if self.query_text else ""
        more = f" · showing the last {len(self.rows):,}" if len(self.rows) < self.matching else ""
        self.set_title(("Event log", "bold"), f"  {n} entries{shown}{more}")

    @on(DataTable.RowHighlighted)
    def _highlighted(self, event: DataTable.RowHighlighted) -> None:
        self._show_entry()

    def _show_entry(self) -> None:
        t = self.query_one(DataTable)
        box = self.query_one("#entry", Static)
        if not self.rows or t.cursor_row >= len(self.rows):
            empty = "no entry matches the filter" if self.query_text else "nothing happened yet"
            box.update(Text(empty, style="dim"))
            return
        seq = self.rows[t.cursor_row]
        e = next((x for x in self.log_.entries if x.seq == seq), None)
        if e is not None:
            box.update(self._entry_text(e))

    def _entry_text(self, e: LogEntry) -> Text:
        """An entry in full: when, what, about whom; by whom, its op and revision."""
        out = Text.assemble(
            (f"{self.clock.stamp_text(e.at)} {e.kind}", "bold"),
            f"  {', '.join(e.robots)}  " if e.robots else "  ",
            e.text,
        )
        who = f"{e.user} on {e.client}" if e.user else e.client
        op = f" · op {e.op}" if e.op else ""
        revision = f" · revision {e.revision}" if e.revision is not None else ""
        out.append(f"\nby {who}{op}{revision}", style="dim")
        return out

    @work(group="dialog")
    async def action_export(self) -> None:
        entries = self.shown_entries()
        path = await self.app.push_screen_wait(
            PathPrompt(
                f"Export {len(entries)} event-log entries (JSON lines) to",
                shown_path(Path.cwd() / "missionctl-log.jsonl"),
                suffixes=(".jsonl",),
            )
        )
        if not path:
            return
        where = shown_path(Path(path))
        try:
            n = self.log_.export(Path(path), entries)
        except OSError as e:
            self.app.notify(f"{where}: {e.strerror or e}", title="Export failed", severity="error")
            return
        self.app.notify(f"{n} entries written to {where}", title="Event log exported")
