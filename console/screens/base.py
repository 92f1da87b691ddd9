"""What the part-2 screens (fleet, event log, alerts, checks) share: a title
bar, the screen-switching keys in the footer, and redrawing when what they
show changed (`changes`, the app's signal of the model's `StateChange`, handed to
the screen with the state it shows) — at once when shown, otherwise when
shown next."""

from __future__ import annotations

from pathlib import Path

from rich.text import Text
from textual import events, on
from textual.app import ComposeResult
from textual.screen import Screen
from textual.signal import Signal
from textual.widgets import DataTable, Input

from console.bindings import bindings
from console.state.changes import StateChange, Topic
from console.widgets.bars import TitleBar

# this module's look (CSS_PATH); absolute, so a subclass defined elsewhere finds it too
TCSS = Path(__file__).with_name("base.tcss")


class ViewScreen(Screen):
    """Layout: title bar, [#filter input], the DataTable (COLUMNS), [.detail], .hint, footer."""

    SCOPE = ""  # the actions.py scope of this screen's own actions
    TOPICS: frozenset[Topic] = frozenset()  # which changes it shows
    COLUMNS: tuple[tuple[str, str], ...] = ()  # (label, key) of the table's columns
    BINDINGS = bindings("app", show=True)

    CSS_PATH = TCSS

    def __init__(self, changes: Signal[StateChange]) -> None:
        super().__init__()
        self.changes = changes
        self._stale = False
        self.ready = False
        self.query_text = ""  # the #filter input's text, if the screen has one
        self._typing = False  # typing from the table into the filter (one word so far)
        self.title_bar = TitleBar(id="title")

    def on_mount(self) -> None:
        table = self.query_one(DataTable)
        for label, key in self.COLUMNS:
            table.add_column(label, key=key)
        self.start()
        # the table first, so the digit keys switch screens; typing starts the filter
        table.focus()

    def start(self) -> None:
        self.changes.subscribe(self, self._changed)
        self.app.theme_changed_signal.subscribe(self, lambda _t: self.redraw())
        self.ready = True
        self.redraw()

    def _changed(self, change: StateChange) -> None:
        if not (change.topics & self.TOPICS) or not self.ready:
            return
        if self.app.screen is self:
            self.update_view(change)
        else:
            self._stale = True

    def on_screen_resume(self) -> None:
        if self._stale:
            self._stale = False
            self.redraw()

    def colour(self, variable: str, fallback: str = "") -> str:
        """A theme variable's colour for Rich text (tables cannot use $vars)."""
        return self.app.theme_variables.get(variable, fallback)

    def set_title(self, *parts: tuple[str, str] | str) -> None:
        self.title_bar.update(Text.assemble(("missionctl", "bold"), "  ", *parts))

    @on(Input.Changed, "#filter")
    def _filter(self, event: Input.Changed) -> None:
        self.query_text = event.value.strip()
        self.redraw()

    @on(Input.Submitted, "#filter")
    def _to_table(self) -> None:
        self._typing = False
        self.query_one(DataTable).focus()

    def on_key(self, event: events.Key) -> None:
        """Type to filter: a printable key the table does not use moves to the
        filter with that character; escape there goes back to the table."""
        filters = self.query("#filter")
        if not filters:
            return
        field = filters.first(Input)
        if field.has_focus:
            if event.key == "escape":
                event.stop()
                self._to_table()
            return
        if event.key in self.app.active_bindings:
            return  # a key with a meaning here (the digits: other screens)
        if event.is_printable and event.character and not event.character.isspace():
            event.stop()
            self._type_into(field, event.character)

    def _type_into(self, field: Input, character: str) -> None:
        field.select_on_focus = False  # else the next key replaces this one
        field.focus()
        field.cursor_position = len(field.value)
        if not self._typing and field.value and not field.value.endswith(" "):
            field.insert_text_at_cursor(" ")  # a new word of the filter (all must match)
        # keys typed before the focus moves come here too: one word until back at the table
        self._typing = True
        field.insert_text_at_cursor(character)

    # subclasses
    def compose(self) -> ComposeResult:  # pragma: no cover - overridden
        yield self.title_bar

    def redraw(self) -> None:
        """Everything again (filter or theme changed, shown after a while)."""

    def update_view(self, change: StateChange) -> None:
        """Something it shows changed while shown (default: redraw)."""
        self.redraw()
