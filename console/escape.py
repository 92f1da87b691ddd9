"""Escape, then a key, over a laggy link (an EscapeSplitter the app owns).

A terminal sends Alt+key as ESC followed by the key; Textual tells the two
apart by time (ESCDELAY, 100 ms). Over SSH the operator's escape and next
key often arrive together and read as Alt+key — which the console binds to
nothing — so the escape was lost and the key typed into a field ("Esc, d"
replaced a label with "d"). The console reads Alt+<printable key> as what
the operator pressed: escape, then the key (an object the app owns: its
`on_event` hands every event to `EscapeSplitter.on_event`).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

from textual import events


def split_escape(key: events.Key) -> tuple[events.Key, events.Key] | None:
    """(escape, the key) for an Alt+<printable key>; None for any other key."""
    if not key.key.startswith("alt+") or not key.character or len(key.character) != 1:
        return None
    if not key.character.isprintable():
        return None
    name = key.key.removeprefix("alt+").removeprefix("shift+")
    plain = name.upper() if key.key.startswith("alt+shift+") else name
    return events.Key("escape", "\x1b"), events.Key(plain, key.character)


class EscapeSplitter:
    def __init__(self, app: Any) -> None:
        self.app = app

    async def on_event(
        self, event: events.Event, deliver: Callable[[events.Event], Awaitable[None]]
    ) -> None:
        """`deliver` an event as Textual would, an Alt+<printable key> as two."""
        is_key = isinstance(event, events.Key) and not event.is_forwarded
        split = split_escape(event) if is_key else None
        if split is None:
            await deliver(event)
            return
        escape, key = split
        # the escape's binding runs now (a forwarded key's would run only
        # after the next key reached the field it was meant to leave)
        if not await self._escape_bound():
            await deliver(escape)  # bound to nothing: as it came
        await deliver(key)

    async def _escape_bound(self) -> bool:
        """Run escape's binding (a priority one first); False when it has none."""
        if await self.app._check_bindings("escape", priority=True):
            return True
        return bool(await self.app._check_bindings("escape"))
