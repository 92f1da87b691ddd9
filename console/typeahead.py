"""Keys typed while a dialog, picker, prompt or the editor opens wait for it.

A key that opens something (the actions table's `opens`: `a` the skill picker,
`/` the search, `enter` the editor, ctrl+p the palette …) takes effect a moment
later: a worker pushes the dialog, the editor rebuilds its fields. Keys typed
meanwhile used to go to the schedule beneath: `a` then `science` typed fast
synchronized a robot (`s`) and duplicated a skill (`c`). From the opening key
on, the app holds the keys it receives (`take`) until the focus has moved —
into the new screen or the editor — and then gives them to it, in order. If
nothing opens (the action did not apply, the question was not needed), the
held keys are dropped and the operator is told: they were typed for
something that did not come, never for the screen beneath.

The app calls `take` first for every event it receives (console/app.py).
"""

from __future__ import annotations

import time
from collections.abc import Awaitable, Callable
from typing import Any

from textual import events
from textual.widgets import Input, TextArea
from textual.worker import WorkerState

from console.bindings import key_names
from console.state.actions import ACTIONS

POLL_S = 0.02  # how often a hold looks whether the focus moved
SETTLE_S = 1.0  # nothing opened and nothing is opening after this: drop what was held
HOLD_S = 5.0  # the longest a hold waits for a dialog that is still being made
OPENING = ("dialog",)  # worker groups that open dialogs


class TypeAhead:
    def __init__(self, app: Any, dispatch: Callable[[events.Key], Awaitable[None]]) -> None:
        self.app = app
        self.dispatch = dispatch  # the app's own handling of a key as it came
        self.held: list[events.Key] = []
        self.what = ""  # the action whose key started the hold ("" : not holding)
        self._since = 0.0
        self._screen: Any = None  # the screen and focus when the opening key came
        self._focus: Any = None
        self._timer: Any = None
        self.dropped = 0  # keys dropped because nothing opened (tests)

    @property
    def holding(self) -> bool:
        return bool(self.what)

    async def take(self, event: events.Event) -> bool:
        """True when the app must not handle `event` now (it is held)."""
        if not isinstance(event, events.Key) or event.is_forwarded:
            return False
        if self.holding:
            self.held.append(events.Key(event.key, event.character))
            return True
        what = self._opens(event)
        if what:  # this key is handled as usual; the next ones wait for what it opens
            self.what, self._since = what, time.monotonic()
            self._screen, self._focus = self.app.screen, self.app.focused
            self._timer = self.app.set_interval(POLL_S, self._poll)
        return False

    def _opens(self, event: events.Key) -> str:
        """The label of the action `event` runs if that opens something, else ''."""
        app = self.app
        focused = app.focused
        if isinstance(focused, Input | TextArea) and event.is_printable:
            return ""  # typed into a field
        screen = app.screen
        scopes = ("app", getattr(screen, "SCOPE", ""))  # a dialog has none: only the app's
        a = _opening_action(key_names(app), event.key, scopes)
        if a is None or not self._acts(a, event.key, screen):
            return ""
        return a.label

    def _acts(self, a: Any, key: str, screen: Any) -> bool:
        """Action `a`, bound to `key`, runs on `screen` (no widget takes the key
        and the screen does not say why it does not apply)."""
        bound = screen.active_bindings.get(key)
        if bound is not None and bound.node not in (screen, self.app):
            return False  # a widget takes this key itself (enter in a list)
        why_not = getattr(screen, "why_disabled", None)
        if a.scope != "app" and why_not is not None and why_not(a.name):
            return False  # it says why it does not apply: nothing opens
        return True

    def _poll(self) -> None:
        self.app.call_next(self._settle)

    def _opening(self) -> bool:
        return any(
            w.group in OPENING and w.state in (WorkerState.PENDING, WorkerState.RUNNING)
            for w in self.app.workers
        )

    async def _settle(self) -> None:
        app = self.app
        if not self.holding or not app.is_running or not app.screen_stack:
            return
        waited = time.monotonic() - self._since
        if self._moved() and app.screen.is_mounted:
            await self._release(app.screen)
        elif waited > HOLD_S or (waited > SETTLE_S and not self._opening()):
            self._drop()

    def _moved(self) -> bool:
        """The screen or the focus is another than when the opening key came."""
        app = self.app
        return app.screen is not self._screen or (
            app.focused is not None and app.focused is not self._focus
        )

    def _stop(self) -> list[events.Key]:
        held, self.held, self.what = self.held, [], ""
        if self._timer is not None:
            self._timer.stop()
            self._timer = None
        return held

    async def _release(self, screen: Any) -> None:
        """Give the held keys to what opened, in order; if it closes meanwhile,
        the rest were typed for it: dropped."""
        held = self._stop()
        for i, key in enumerate(held):
            if self.app.screen is not screen:
                self._said_dropped(len(held) - i, "it closed")
                return
            await self.dispatch(key)

    def _drop(self) -> None:
        what = self.what
        held = self._stop()
        if held:
            self._said_dropped(len(held), f"{what} did not open")

    def _said_dropped(self, n: int, why: str) -> None:
        self.dropped += n
        self.app.notify(
            f"{n} key{'s' if n != 1 else ''} typed for it {'were' if n != 1 else 'was'} "
            f"dropped ({why}): nothing else received them",
            title="Keys dropped",
            severity="warning",
            timeout=4,
        )


def _opening_action(keys: Any, key: str, scopes: tuple[str, ...]) -> Any:
    """The first action of `scopes` that opens something and runs on `key`, or None."""
    return next(
        (
            a
            for a in ACTIONS
            if a.opens and a.scope in scopes and key in keys.keys(a.binding_id).split(",")
        ),
        None,
    )
