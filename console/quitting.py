"""Quitting: asked first while something is under way (an object the app owns).

Robots executing, commands not yet acknowledged, plan edits not saved to a
file (console/state/model.py `quit_risks`) and unapplied changes in the
editor each make ctrl+q ask; the question says what quitting does to them
(the demo: everything stops) and offers to save the mission first.
`ask_before_quit` False (`--yes`) never asks.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

from console.screens.dialogs import QuitScreen
from console.state.model import ConsoleModel


class QuitPolicy:
    def __init__(
        self,
        app: Any,
        model: ConsoleModel,
        quit_now: Callable[[], Awaitable[None]],
        *,
        ask: bool = True,
        stops: str = "",
    ) -> None:
        self.app = app
        self.model = model
        self.quit_now = quit_now
        self.ask = ask  # False: --yes
        self.stops = stops  # what else ends with the console (the demo)

    async def quit(self) -> None:
        """Ctrl+Q: asks first when robots are executing, commands are not yet
        acknowledged, the plan has unsaved edits or the editor unapplied
        changes (`ask` False: never)."""
        if isinstance(self.app.screen, QuitScreen):
            return  # it handles ctrl+q itself
        risks = self.risks() if self.ask else []
        if not risks:
            await self.quit_now()
            return
        consequence = self.stops or (
            "The server keeps the mission; the robots go on executing, watched by no one from here."
        )
        can_save = self.model.unsaved and self._mission_screen() is not None
        self.app.push_screen(QuitScreen(risks, consequence, can_save=can_save), self._answered)

    def risks(self) -> list[str]:
        """What quitting now walks away from (console/state/model.py), and
        the editor's unapplied changes."""
        risks = self.model.quit_risks()
        unapplied = self._unapplied()
        if unapplied:
            risks.append(f"unapplied changes in the editor to {', '.join(unapplied)}")
        return risks

    def _mission_screen(self) -> Any:
        s = self.app.mission_screen
        return s if s is not None and s.is_mounted else None

    def _unapplied(self) -> list[str]:
        s = self._mission_screen()
        if s is None:
            return []
        return sorted(s.editor.drafts) + (
            [s.editor.skill_id] if s.editor.dirty and s.editor.skill_id else []
        )

    def _answered(self, answer: str | None) -> None:
        if answer == "quit":
            self.app.run_worker(self.quit_now(), group="quit")
        elif answer == "save":
            self.app.run_worker(self._save_then_quit(), group="quit")

    async def _save_then_quit(self) -> None:
        s = self.app.mission_screen
        if s is not None and await s.files.save_mission():
            await self.quit_now()
