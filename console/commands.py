"""Command palette entries for every operator action (ctrl+p).

Each entry says its key, and when it does not apply to the current
selection, why; choosing such an entry explains instead of acting.
"""

from __future__ import annotations

from functools import partial
from typing import Any

from textual.command import DiscoveryHit, Hit, Hits, Provider

from .actions import ACTIONS


class MissionCommands(Provider):
    def _screen(self, scope: str = "mission") -> Any:
        if scope == "map":  # map actions: only while the map is shown
            screen = getattr(self.app, "map_screen", None)
            return screen if screen is not None and self.app.screen is screen else None
        return getattr(self.app, "mission_screen", None)

    def _entries(self):
        keys = getattr(self.app, "action_keys", lambda: {})()
        for a in ACTIONS:
            if a.scope == "app":
                yield a, f"{keys.get(a.name, a.key)} · {a.description}", partial(self.app.run_action, a.name)
                continue
            screen = self._screen(a.scope)
            if screen is None:
                continue
            why = screen.why_disabled(a.name) if hasattr(screen, "why_disabled") else None
            key = keys.get(a.name, a.key)
            help_text = f"{key} · {a.description}" + (f" — does not apply now: {why}" if why else "")
            yield a, help_text, partial(self._run, a.name, a.scope)

    async def _run(self, name: str, scope: str = "mission") -> None:
        screen = self._screen(scope)
        if screen is not None:
            await screen.run_named(name)

    async def discover(self) -> Hits:
        for a, help_text, run in self._entries():
            yield DiscoveryHit(f"{a.group if a.scope != 'mission' else 'Mission'}: {a.label}", run, help=help_text)

    async def search(self, query: str) -> Hits:
        matcher = self.matcher(query)
        for a, help_text, run in self._entries():
            text = f"{a.group if a.scope != 'mission' else 'Mission'}: {a.label}"
            score = max(matcher.match(text), matcher.match(a.description) * 0.5)
            if score > 0:
                yield Hit(score, matcher.highlight(text), run, text=text, help=help_text)
