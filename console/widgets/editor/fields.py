"""The editor's fields: Textual's inputs, made to keep every key of a burst.

Textual runs a widget's key bindings (backspace, end, enter …) only after
the key has bubbled up to the app, while it inserts printable characters at
once, in the widget. Typed fast — over SSH a burst arrives at once — the two
overtake each other: `End`, 30 backspaces and "explore SE quadrant" left
"survey beyon". These fields run their own bindings as the key arrives, in
order with the characters (`InOrder`).

Enter applies the form from every kind of field: an input submits, a closed
choice or a switch posts `EnterPressed` (they opened or toggled before; space
still does); a text area keeps enter for its lines. ctrl+a selects all of a
text area (a polygon's points), as the actions table says.
"""

from __future__ import annotations

from typing import Any

from textual import events
from textual.message import Message
from textual.widgets import Input, Switch, TextArea

from console.bindings import bind
from console.widgets.select import SafeSelect


class EnterPressed(Message):
    """Enter on a field that does not submit by itself: apply the form."""


class InOrder:
    """Run this widget's own binding for a key when the key arrives."""

    async def _on_key(self, event: events.Key) -> None:
        widget: Any = self
        for binding in widget._bindings.key_to_bindings.get(event.key, ()):
            if binding.priority:
                continue  # the app ran those before the key came here
            event.stop()
            event.prevent_default()
            await widget.run_action(binding.action)
            return
        await super()._on_key(event)  # type: ignore[misc]


class FieldInput(InOrder, Input):
    pass


class FieldArea(InOrder, TextArea):
    BINDINGS = [bind("editor.select_all", "select_all")]


class FieldSelect(InOrder, SafeSelect):
    """A choice: enter applies the form (up, down and space open the list)."""

    BINDINGS = [bind("editor.apply", "apply_form")]

    def action_apply_form(self) -> None:
        self.post_message(EnterPressed())


class FieldSwitch(InOrder, Switch):
    """A yes/no: enter applies the form (space switches it)."""

    BINDINGS = [bind("editor.apply", "apply_form")]

    def action_apply_form(self) -> None:
        self.post_message(EnterPressed())
