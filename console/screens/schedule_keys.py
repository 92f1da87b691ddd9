"""The schedule screen's keys: which action a key runs, and whether it may.

The mission screen dispatches the actions table's keys itself as they pass
it (`MissionScreen.on_key`), so a key typed on another screen — a dialog that
closed while the key was on its way — never reaches them. A widget that binds
the key itself keeps it (enter in a field); a key that sends a command to a
robot acts only on a press made on the schedule itself.
"""

from __future__ import annotations

from typing import Any

from textual import events

from console.bindings import key_names, mission_keys
from console.state.actions import BY_NAME
from console.state.context import (
    EDITOR,
    FooterKey,
    context_keys,
    fit_footer,
    footer_keys,
    tail_keys,
)
from console.state.keys import KeyNames


def schedule_action(screen: Any, event: events.Key) -> str | None:
    """The mission action `event` runs on `screen` now (None: not one of its keys)."""
    action = mission_keys(key_names(screen)).get(event.key)
    if action is None:
        return None
    bound = screen.active_bindings.get(event.key)
    if bound is not None and bound.node not in (screen, screen.app):
        return None  # a widget binds this key itself
    return action


def refused_off_schedule(screen: Any, action: str, event: events.Key) -> str | None:
    """Why a robot command's key does not act here (None: it may)."""
    a = BY_NAME[action]
    if not a.to_robot or screen.schedule.last_key is event:
        return None
    back = key_names(screen).say("editor.leave")
    return (
        f"{a.label} sends a command to a robot: it acts only on a press on the "
        f"schedule ({back} returns there)"
    )


def added_text(keys: KeyNames, what: str) -> str:
    """After an add: what was added, and the key that applies its parameters."""
    return f"added {what}: set its parameters; {keys.say('editor.apply')} in a field applies them"


def footer_now(screen: Any) -> list[FooterKey]:
    """The footer: the editor's keys while it has the focus, else the keys that
    apply to the selection, most likely first (console/state/context.py)."""
    keys = key_names(screen)
    if screen.editor.focus_within():
        first = footer_keys(EDITOR, keys)
    else:
        robot, sid = screen.selection()
        first = context_keys(screen.model, robot, sid, screen.schedule.marks, keys)
    return fit_footer(first, screen.size.width or screen.app.size.width, tail_keys(keys))
