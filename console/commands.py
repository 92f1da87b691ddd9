"""Command palette entries for every operator action (ctrl+p).

Each entry says its key, and when it does not apply to the current
selection, why; choosing such an entry explains instead of acting.
"""

from __future__ import annotations

from functools import partial
from typing import Any

from textual.command import DiscoveryHit, Hit, Hits, Provider

from console.bindings import key_names
from console.screens.cancel import ask_and_cancel, toast_say
from console.screens.question import open_question
from console.state import link
from console.state.actions import ACTIONS
from console.state.questions import due_text, open_questions, palette_title


def _help(keys: Any, a: Any, why: str | None) -> str:
    """An entry's help: its keys, what it does, and why it does not apply now."""
    return f"{keys.all(a.binding_id)} · {a.description}" + (
        f" — does not apply now: {why}" if why else ""
    )


class MissionCommands(Provider):
    def _screen(self) -> Any:
        return getattr(self.app, "mission_screen", None)

    def _entries(self):
        screen = self._screen()
        if screen is None:
            return
        keys = key_names(self)
        # the screen the palette was opened on (its own actions are offered too)
        here = getattr(self.screen, "SCOPE", "mission") if self.screen is not screen else "mission"
        for a in ACTIONS:
            if a.scope not in ("mission", "app", here) or a.fixed or a.name == "command_palette":
                continue
            why = screen.why_disabled(a.name) if a.scope == "mission" else None
            yield a, _help(keys, a, why), partial(self._run, a)

    def _cancels(self):
        """Every pending command, to cancel (asks first)."""
        screen = self._screen()
        m = screen.model if screen is not None else None
        if m is None or m.mission is None:
            return
        for c in m.mission.pending_commands():
            what = f" ({', '.join(c.skills)})" if c.skills else ""
            title = f"Cancel {c.op} #{c.id} to {c.robot}{what}"
            help_text = f"{link.command_text(c, m.clock)} · asks first"
            yield title, help_text, partial(self._cancel, c)

    def _questions(self):
        """Every open question of a robot, to answer."""
        m = getattr(self.app, "model", None)
        if m is None:
            return
        for q in open_questions(m.mission):
            due = due_text(q, m.clock, link.robot_delay_s(m.robots, q.robot))
            help_text = f"{q.text} · {due}"
            yield palette_title(q), help_text, partial(open_question, self.app, q.id)

    def _offers(self):
        """The pending commands to cancel and the questions to answer."""
        yield from self._cancels()
        yield from self._questions()

    def _cancel(self, c) -> None:
        screen = self._screen()
        say = screen.say if self.app.screen is screen else toast_say(self.app)
        screen.run_worker(ask_and_cancel(screen, screen.ops, c, say), group="dialog")

    async def _run(self, a) -> None:
        if a.scope == "mission":
            screen = self._screen()
            if screen is not None:
                await screen.run_named(a.name)
        elif a.scope == "app":
            await self.app.run_action(a.name)
        elif hasattr(self.screen, "run_named"):  # it explains what does not apply (the map)
            await self.screen.run_named(a.name)
        else:
            await self.screen.run_action(a.name)

    async def discover(self) -> Hits:
        for a, help_text, run in self._entries():
            yield DiscoveryHit(a.palette_title, run, help=help_text)
        for title, help_text, run in self._offers():
            yield DiscoveryHit(title, run, help=help_text)

    async def search(self, query: str) -> Hits:
        matcher = self.matcher(query)
        for a, help_text, run in self._entries():
            text = a.palette_title
            score = max(matcher.match(text), matcher.match(a.description) * 0.5)
            if score > 0:
                yield Hit(score, matcher.highlight(text), run, text=text, help=help_text)
        for title, help_text, run in self._offers():
            score = matcher.match(title)
            if score > 0:
                yield Hit(score, matcher.highlight(title), run, text=title, help=help_text)
