"""The mission screen's file actions: save the mission to YAML, its state or
a plan (its skill library beside it when the mission's reference would not
resolve from there: backend.files.missions.save_mission_file, as `ctl save`)
and load one, which replaces the plan for every operator (asked first: as a
plan, or keeping the file's statuses).
The path prompt shows the full path, completes, lists recent files and asks
before replacing a file (console/state/files.py says when). An object the
mission screen owns (console/screens/mission.py)."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from rich.text import Text

from backend.core.model import Mission
from backend.core.ops import LoadMission
from backend.files.missions import library_beside, save_mission_file
from console.screens.dialogs import ChoiceScreen, PathPrompt
from console.state.files import RecentFiles, default_save_path, shown_path


class FileActions:
    """ctrl+s saves, ctrl+o loads (actions of the mission screen)."""

    def __init__(self, screen: Any, recent: RecentFiles) -> None:
        self.screen = screen  # MissionScreen: say, submit, app
        self.model = screen.model
        self.recent = recent  # saved and loaded files, newest first
        self.last_path: str | None = None  # of the last save or load: the next one's default

    @property
    def app(self) -> Any:
        return self.screen.app

    def say(self, text: str, severity: str = "info") -> None:
        self.screen.say(text, severity)

    async def save_mission(self) -> bool:
        """Ask where, (ask before replacing a file), save; True when saved."""
        m, lib = self.model.mission, self.model.library
        if m is None or lib is None:
            return False
        default = default_save_path(m.name, self.last_path, self.recent.files, Path.cwd())
        path = await self.app.push_screen_wait(
            PathPrompt(
                f"Save '{m.name}' (revision {m.revision}) to the YAML file:",
                shown_path(default),
                recent=self.recent.files,
                suffixes=YAML,
                also_writes=lambda p: [b] if (b := library_beside(m, lib, p)) is not None else [],
            )
        )
        what = path and await self.app.push_screen_wait(
            ChoiceScreen(f"Save '{m.name}' as:", SAVE_AS)
        )
        if not path or not what:
            self.say("not saved")
            return False
        target = Path(path)
        try:
            saved = await asyncio.to_thread(save_mission_file, m, lib, target, what)
        except OSError as e:
            self.say(f"cannot save {target.name}: {e.strerror or e}", "error")
            self.app.notify(
                f"{shown_path(target)}: {e.strerror or e}", title="Not saved", severity="error"
            )
            return False
        self._saved(path, what, m.revision, saved.library_file)
        return True

    def _saved(self, path: str, what: str, revision: int, library_file: Path | None) -> None:
        """Remember the file, and say what was written where."""
        target = Path(path)
        self.last_path = path
        self.recent.add(path)
        self.model.mark_saved()
        beside = f"; its skill library written to {library_file.name}" if library_file else ""
        where = shown_path(target.parent)
        self.say(f"saved {target.name} ({what}, revision {revision}) in {where}{beside}", "ok")
        self.app.notify(shown_path(target), title="Mission saved", timeout=4)

    async def load(self) -> None:
        start = self.last_path or (
            shown_path(Path(self.recent.files[0]).parent) + "/" if self.recent.files else ""
        )
        path = await self.app.push_screen_wait(
            PathPrompt(
                "Load a mission from the YAML file:",
                start or shown_path(Path.cwd()) + "/",
                must_exist=True,
                recent=self.recent.existing(),
                suffixes=YAML,
            )
        )
        if not path:
            return
        mission = await self._read(path)
        if mission is None:
            return
        how = await self.app.push_screen_wait(
            ChoiceScreen(
                f"Replace the mission with {shown_path(Path(path))} ('{mission.name}')? "
                "The current plan is replaced for every operator.",
                LOAD_AS,
            )
        )
        if how not in ("plan", "state"):
            return
        self.last_path = path
        self.recent.add(path)
        name = Path(path).name

        def loaded(reply: Any) -> None:
            self.model.mark_saved()  # the plan is the file's now
            self.say(f"loaded {name}: '{mission.name}'", "ok")

        op = LoadMission(mission=mission, keep_state=how == "state")
        self.screen.submit(op, f"load {name}", then=loaded)

    async def _read(self, path: str) -> Mission | None:
        """The mission in the file, or None when it cannot be read (said)."""
        from backend.files.diagnostics import FileProblems
        from backend.files.missions import load_mission

        name = Path(path).name
        try:
            mission, _lib = await asyncio.to_thread(load_mission, path)
        except FileProblems as e:
            first = str(e.issues[0]) if e.issues else str(e)
            more = f" (and {len(e.issues) - 1} more)" if len(e.issues) > 1 else ""
            self.say(f"cannot load {name}: {first}{more}", "error")
            self.app.notify(first + more, title="Mission file invalid", severity="error")
            return None
        except OSError as e:
            self.say(f"cannot load {name}: {e.strerror or e}", "error")
            return None
        return mission


YAML = (".yaml", ".yml")
SAVE_AS = [
    ("state", Text("its state: the statuses and the log as they are")),
    ("plan", Text("a plan: every skill idle, to run again")),
]
# starts on Cancel: enter alone never replaces the mission
LOAD_AS = [
    ("cancel", Text("Cancel")),
    ("plan", Text("Replace, as a plan: unfinished skills idle, the log kept")),
    ("state", Text("Replace, keeping the file's statuses (refused while its robots are online)")),
]
