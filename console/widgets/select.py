"""Textual's `Select`, safe to tear down while it is being updated.

Textual 8.2's Select looks up its overlay child in its mount handler and its
value watcher. When the editor rebuilds its fields (a resync, a quick change
of skill) a Select can be removed between those: its overlay goes first, the
lookup raises NoMatches, and the unhandled exception ends the console.
"""

from __future__ import annotations

from typing import Any

from textual import events
from textual.css.query import NoMatches
from textual.widgets import Select


class SafeSelect(Select):
    def _on_mount(self, event: events.Mount) -> None:
        try:
            super()._on_mount(event)
        except NoMatches:  # removed before it was set up: nothing left to show
            pass

    def _watch_value(self, value: Any) -> None:
        try:
            super()._watch_value(value)
        except NoMatches:  # being removed (its overlay already gone)
            pass
