"""The map screen's marker actions: add one at the cursor, move the selected
one there, rename or delete it (an object the screen owns; its keys call
these). Each goes through the operations as everywhere (backend.core.ops)."""

from __future__ import annotations

from typing import Any

from backend.core.model import Marker
from backend.core.ops import MarkerAdd, MarkerDelete, MarkerMove, MarkerRename
from console.screens.dialogs import ConfirmScreen, MarkerPrompt
from console.state.markers import followers, free_name, moved_value, new_marker
from console.state.model import CONNECTED


def _they(names: list[str], verb: str) -> str:
    """'lru1 follows', 'lru1, lru2 follow'."""
    return f"{', '.join(names)} {verb}{'s' if len(names) == 1 else ''}"


def moved_text(name: str, cursor: tuple[float, float], following: list[str], reply: Any) -> str:
    """What moving a marker did: where to, who follows it, who still uses the old value."""
    x, y = cursor
    text = f"moved {name} to ({x:.1f}, {y:.1f})"
    if following:
        text += f"; {_they(following, 'follow')}"
    stale = reply.value.get("stale", [])
    if stale:
        text += f"; {_they(stale, 'still use')} the old value — unsynchronize to update"
    return text


class MarkerActions:
    def __init__(self, screen: Any) -> None:
        self.screen = screen  # MapScreen: model, view, say, submit, app
        self.view = screen.view

    def _connected(self) -> bool:
        s = self.screen
        if s.model.connection != CONNECTED:
            s.say(
                f"not connected to the mission server ({s.model.connection}): "
                "markers cannot be changed now",
                "warning",
            )
            return False
        return True

    def selected(self) -> Marker | None:
        """The selected marker (None: none, and the operator is told how to select one)."""
        name = self.view.selected_marker
        m = self.screen.model.mission
        if name is None or m is None or name not in m.markers:
            self.screen.say(
                "select a marker first: n selects the next one (the cursor jumps to it)", "warning"
            )
            return None
        return m.markers[name]

    def _cursor(self) -> tuple[float, float]:
        x, y = (round(c, 1) for c in self.view.cursor)
        return x, y

    async def add(self) -> None:
        s = self.screen
        if not self._connected():
            return
        answer = await s.app.push_screen_wait(
            MarkerPrompt("New marker at the cursor — name:", free_name(s.model.mission))
        )
        if not answer:
            return
        name, kind = answer
        x, y = self._cursor()
        marker = new_marker(kind, x, y, self.view.heading, self.view.vp.mpp)

        def ok(reply: Any) -> None:
            self.view.selected_marker = name
            s.say(f"added {kind} marker {name} at ({x:g}, {y:g})", "ok")

        s.submit(MarkerAdd(name=name, marker=marker), f"add marker {name}", on_ok=ok)

    def move(self) -> None:
        s = self.screen
        mk = self.selected()
        if mk is None or not self._connected():
            return
        name = self.view.selected_marker
        following = followers(s.model.mission, name)
        value = moved_value(mk, *self._cursor(), self.view.heading)

        def ok(reply: Any) -> None:
            text = moved_text(name, self.view.cursor, following, reply)
            s.say(text, "warning" if reply.value.get("stale") else "ok")

        s.submit(MarkerMove(name=name, value=value), f"move marker {name}", on_ok=ok)

    async def rename(self) -> None:
        s = self.screen
        if self.selected() is None or not self._connected():
            return
        old = self.view.selected_marker
        answer = await s.app.push_screen_wait(
            MarkerPrompt(f"Rename marker {old} to:", old, kinds=False)
        )
        if not answer or answer[0] == old:
            return
        new = answer[0]

        def ok(reply: Any) -> None:
            self.view.selected_marker = new
            s.say(f"renamed {old} to {new}", "ok")

        s.submit(MarkerRename(name=old, new_name=new), f"rename marker {old}", on_ok=ok)

    async def delete(self) -> None:
        s = self.screen
        if self.selected() is None or not self._connected():
            return
        name = self.view.selected_marker
        question = f"Delete marker {name}? Idle skills bound to it keep its value."
        if not await s.app.push_screen_wait(ConfirmScreen(question, yes="Delete")):
            s.say("delete cancelled")
            return

        def ok(reply: Any) -> None:
            self.view.selected_marker = None
            s.say(f"deleted marker {name}", "ok")

        s.submit(MarkerDelete(name=name), f"delete marker {name}", on_ok=ok)
