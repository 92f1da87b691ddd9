"""Textual key bindings, generated from the actions table (console/state/actions.py,
which stays Textual-free), and the keys as the user has them (their keymap)."""

from __future__ import annotations

from typing import Any

from textual.binding import Binding

from console.state.actions import ACTIONS, BY_ID, Action
from console.state.keys import KeyNames


def _binding(a: Action, action: str, show: bool, priority: bool | None) -> Binding:
    return Binding(
        a.key,
        action,
        a.label,
        show=show,
        id=a.binding_id,
        tooltip=a.description,
        priority=a.priority if priority is None else priority,
    )


def bindings(
    scope: str = "mission", *, show: bool | None = None, actions: list[Action] = ACTIONS
) -> list[Binding]:
    """Bindings of one scope; `show` overrides the footer flag (app-wide keys
    are bound twice: hidden on the app, shown by the part-2 screens)."""
    return [
        _binding(
            a,
            f"app.{a.name}" if scope == "app" else a.name,
            a.footer if show is None else show,
            None,
        )
        for a in actions
        if a.scope == scope and a.bound
    ]


def bind(
    binding_id: str,
    action: str,
    *,
    show: bool | None = None,
    priority: bool | None = None,
) -> Binding:
    """The binding of one action of the table where it applies ("dialog.cancel" on a dialog)."""
    a = BY_ID[binding_id]
    return _binding(a, action, a.footer if show is None else show, priority)


def mission_keys(keys: KeyNames) -> dict[str, str]:
    """Key -> the schedule screen's action it runs (the user's keymap applied)."""
    return {
        key: a.name
        for a in ACTIONS
        if a.scope == "mission"
        for key in keys.keys(a.binding_id).split(",")
    }


def key_names(node: Any) -> KeyNames:
    """The keys as this app has them: the table's, remapped by the user's keymap."""
    return KeyNames(getattr(node.app, "_keymap", None) or {})
