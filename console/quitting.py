"""Quitting: asked first while something is under way (mixed into the app).

Robots executing, commands not yet acknowledged, plan edits not saved to a
file (console/state/model.py `quit_risks`) and unapplied changes in the
editor each make ctrl+q ask; the question says what quitting does to them
(the demo: everything stops) and offers to save the mission first.
`ask_before_quit` False (`--yes`) never asks.
"""

from __future__ import annotations

from typing import Any

from textual.app import App

from console.screens.dialogs import QuitScreen


class QuitQuestion(App[int]):
    ask_before_quit: bool
    quitting_stops: str
    model: Any
    mission_screen: Any

    def _screen_live(self) -> bool: ...
    async def quit_now(self) -> None: ...

    async def action_quit(self) -> None:
        """Ctrl+Q: asks first when robots are executing, commands are not yet
        acknowledged, the plan has unsaved edits or the editor unapplied
        changes (`ask_before_quit` False: never)."""
        if isinstance(self.screen, QuitScreen):
            return  # it handles ctrl+q itself
        risks = self.quit_risks() if self.ask_before_quit else []
        if not risks:
            await self.quit_now()
            return
        consequence = self.quitting_stops or (
            "The server keeps the mission; the robots go on executing, watched by no one from here."
        )
        can_save = self.model.unsaved and self._screen_live()
        self.push_screen(QuitScreen(risks, consequence, can_save=can_save), self._quit_answered)

    def quit_risks(self) -> list[str]:
        """What quitting now walks away from (console/state/model.py), and
        the editor's unapplied changes."""
        risks = self.model.quit_risks()
        unapplied = self._unapplied()
        if unapplied:
            risks.append(f"unapplied changes in the editor to {', '.join(unapplied)}")
        return risks

    def _unapplied(self) -> list[str]:
        s = self.mission_screen
        if s is None or not s.is_mounted:
            return []
        return sorted(s.editor.drafts) + (
            [s.editor.skill_id] if s.editor.dirty and s.editor.skill_id else []
        )

    def _quit_answered(self, answer: str | None) -> None:
        if answer == "quit":
            self.run_worker(self.quit_now(), group="quit")
        elif answer == "save":
            self.run_worker(self._save_then_quit(), group="quit")

    async def _save_then_quit(self) -> None:
        if self.mission_screen is not None and await self.mission_screen.save_mission():
            await self.quit_now()
