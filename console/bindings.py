"""Textual key bindings, generated from the actions table (console/state/actions.py,
which stays Textual-free)."""

from __future__ import annotations

from textual.binding import Binding

from console.state.actions import ACTIONS, Action


def bindings(
    scope: str = "mission", *, show: bool | None = None, actions: list[Action] = ACTIONS
) -> list[Binding]:
    """Bindings of one scope; `show` overrides the footer flag (app-wide keys
    are bound twice: hidden on the app, shown by the part-2 screens)."""
    return [
        Binding(
            a.key,
            f"app.{a.name}" if scope == "app" else a.name,
            a.label,
            show=a.footer if show is None else show,
            id=a.binding_id,
            tooltip=a.description,
        )
        for a in actions
        if a.scope == scope
    ]


def mission_bindings() -> list[Binding]:
    return bindings("mission")
