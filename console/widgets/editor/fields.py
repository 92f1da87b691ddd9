"""The editor's fields: Textual's inputs, made to keep every key of a burst.

Textual runs a widget's key bindings (backspace, end, enter …) only after
the key has bubbled up to the app, while it inserts printable characters at
once, in the widget. Typed fast — over SSH a burst arrives at once — the two
overtake each other: `End`, 30 backspaces and "explore SE quadrant" left
"survey beyon". These fields run their own bindings as the key arrives, in
order with the characters (`in_order`).

Enter applies the form from every kind of field: an input submits, a closed
choice or a switch posts `EnterPressed` (they opened or toggled before; space
still does); a text area keeps enter for its lines. ctrl+a selects all of a
text area (a polygon's points), as the actions table says.
"""

from __future__ import annotations

from typing import Any, TypeVar

from textual import events
from textual.message import Message
from textual.widget import Widget
from textual.widgets import Input, Switch, TextArea

from console.bindings import bind
from console.widgets.select import SafeSelect

W = TypeVar("W", bound=Widget)


class EnterPressed(Message):
    """Enter on a field that does not submit by itself: apply the form."""


async def ran_in_order(widget: Any, event: events.Key) -> bool:
    """Run `widget`'s own binding for a key as the key arrives (True: it had one)."""
    for binding in widget._bindings.key_to_bindings.get(event.key, ()):
        if binding.priority:
            continue  # the app ran those before the key came here
        event.stop()
        event.prevent_default()
        await widget.run_action(binding.action)
        return True
    return False


def in_order(cls: type[W]) -> type[W]:
    """A field class that runs its own bindings as a key arrives, then Textual's handling."""
    textuals = cls._on_key

    async def _on_key(self: Any, event: events.Key) -> None:
        if not await ran_in_order(self, event):
            await textuals(self, event)

    cls._on_key = _on_key  # type: ignore[method-assign]
    return cls


@in_order
class FieldInput(Input):
    pass


@in_order
class FieldArea(TextArea):
    BINDINGS = [bind("editor.select_all", "select_all")]


@in_order
class FieldSelect(SafeSelect):
    """A choice: enter applies the form (up, down and space open the list)."""

    BINDINGS = [bind("editor.apply", "apply_form")]

    def action_apply_form(self) -> None:
        self.post_message(EnterPressed())


@in_order
class FieldSwitch(Switch):
    """A yes/no: enter applies the form (space switches it)."""

    BINDINGS = [bind("editor.apply", "apply_form")]

    def action_apply_form(self) -> None:
        self.post_message(EnterPressed())
