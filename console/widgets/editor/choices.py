"""The form's marker choices: a pose, position or area parameter bound to a
marker has its typed fields disabled; choosing another marker renames it in
a label that named the old one ("drive to POI-A" -> "drive to POI-B")."""

from __future__ import annotations

from typing import Any

from textual.dom import DOMNode
from textual.widgets import Input, Select

from console.state.markers import relabel
from console.widgets.editor.inputs import TYPED, read_binding


def chosen(select: Select[Any]) -> str | None:
    """The marker a choice shows (None: a typed value, or none)."""
    return None if select.value in (TYPED, Select.NULL) else str(select.value)


class MarkerChoices:
    def __init__(self, form: DOMNode) -> None:
        self.form = form
        self.shown: dict[str, str | None] = {}  # Select id -> the marker it showed

    def remember(self) -> None:
        """What each choice of a newly composed form shows."""
        self.shown = {w.id: chosen(w) for w in self.form.query(Select) if w.id}

    def relabel(self, widget_id: str) -> None:
        """A marker chosen instead of another: a label naming the old marker
        names the new one, in the label field (applied with the rest, or reverted)."""
        try:
            select = self.form.query_one(f"#{widget_id}", Select)
            label = self.form.query_one("#f-label", Input)
        except Exception:
            return  # not a choice (or being rebuilt)
        before, self.shown[widget_id] = self.shown.get(widget_id), chosen(select)
        new = relabel(label.value, before, self.shown[widget_id])
        if new is not None:
            label.value = new

    def sync_bound(self, name: str, read_only: bool) -> None:
        """A bound parameter's typed fields are off (all are, read-only)."""
        off = read_only or read_binding(self.form, name) is not None
        for w in self.form.query(f"#param-{name} Input, #param-{name} TextArea"):
            w.disabled = off

    def sync_all_bound(self, read_only: bool) -> None:
        for w in self.form.query(Select):
            if w.id and w.id.startswith("bind-"):
                self.sync_bound(w.id.removeprefix("bind-"), read_only)
