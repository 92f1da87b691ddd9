"""The mission screen's file actions: save the mission to YAML (its skill
library beside it when the mission's reference would not resolve from
there) and load one, which replaces the plan for every operator (asked first).
The path prompt shows the full path, completes, lists recent files and asks
before replacing a file (console/state/files.py says when). An object the
mission screen owns (console/screens/mission.py)."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from backend.core.ops import LoadMission
from console.screens.dialogs import ConfirmScreen, PathPrompt
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
                also_writes=lambda p: [b] if (b := library_beside(m, p)) is not None else [],
            )
        )
        if not path:
            self.say("not saved")
            return False
        target = Path(path)
        try:
            note = await asyncio.to_thread(save_with_library, m, lib, target)
        except OSError as e:
            self.say(f"cannot save {target.name}: {e.strerror or e}", "error")
            self.app.notify(
                f"{shown_path(target)}: {e.strerror or e}", title="Not saved", severity="error"
            )
            return False
        self.last_path = path
        self.recent.add(path)
        self.model.mark_saved()
        self.say(
            f"saved {target.name} (revision {m.revision}) in {shown_path(target.parent)}"
            + (f"; {note}" if note else ""),
            "ok",
        )
        self.app.notify(shown_path(target), title="Mission saved", timeout=4)
        return True

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
            return
        except OSError as e:
            self.say(f"cannot load {name}: {e.strerror or e}", "error")
            return
        if not await self.app.push_screen_wait(
            ConfirmScreen(
                f"Replace the mission with {shown_path(Path(path))} ('{mission.name}')? "
                "The current plan is replaced for every operator.",
                yes="Replace",
            )
        ):
            return
        self.last_path = path
        self.recent.add(path)

        def loaded(reply: Any) -> None:
            self.model.mark_saved()  # the plan is the file's now
            self.say(f"loaded {name}: '{mission.name}'", "ok")

        self.screen.submit(LoadMission(mission=mission), f"load {name}", then=loaded)


YAML = (".yaml", ".yml")


def library_beside(mission: Any, path: Path) -> Path | None:
    """The skill library file a save to `path` writes beside it: when the
    mission's library reference would not resolve from there (else None)."""
    from backend.files.missions import library_path

    if library_path(path, mission.library).exists():
        return None
    return path.with_name(path.stem + ".library.yaml")


def save_with_library(mission: Any, library: Any, path: Path) -> str:
    """Save the mission; if its library reference does not resolve from the
    new place, write the library beside it and point there (the prompt asked
    before either file was replaced)."""
    from backend.files import yamlio
    from backend.files.missions import save_mission

    beside = library_beside(mission, path)
    if beside is None:
        save_mission(mission, path)
        return ""
    beside.write_text(
        yamlio.dump(
            library.model_dump(mode="json", exclude_defaults=True) | {"format": library.format}
        ),
        encoding="utf-8",
    )
    save_mission(mission, path, library_file=beside)
    return f"its skill library written to {beside.name}"
