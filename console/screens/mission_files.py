"""The mission screen's file actions: save the mission to YAML (its skill
library beside it when the mission's reference would not resolve from
there) and load one, which replaces the plan for every operator (asked first).
Mixed into `MissionScreen` (console/screens/mission.py)."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import TYPE_CHECKING, Any

from textual import work

from backend.core.ops import LoadMission
from console.screens.dialogs import ConfirmScreen, PathPrompt
from console.state.model import ConsoleModel

if TYPE_CHECKING:
    from textual.app import App


class MissionFiles:
    """ctrl+s saves, ctrl+o loads (actions of the mission screen)."""

    model: ConsoleModel
    last_path: str | None  # of the last save or load: the next one's default
    app: App[Any]

    def say(self, text: str, severity: str = "info") -> None: ...
    def submit(self, op: Any, what: str, **kw: Any) -> None: ...

    @work(group="dialog")
    async def action_save(self) -> None:
        m, lib = self.model.mission, self.model.library
        if m is None or lib is None:
            return
        default = self.last_path or f"{m.name.lower().replace(' ', '_')}.yaml"
        path = await self.app.push_screen_wait(PathPrompt("Save the mission to (YAML):", default))
        if not path:
            return
        try:
            note = await asyncio.to_thread(save_with_library, m, lib, Path(path))
        except OSError as e:
            self.say(f"cannot save {path}: {e.strerror or e}", "error")
            self.app.notify(f"{path}: {e.strerror or e}", title="Not saved", severity="error")
            return
        self.last_path = path
        self.say(f"saved {path} (revision {m.revision})" + (f"; {note}" if note else ""), "ok")

    @work(group="dialog")
    async def action_load(self) -> None:
        path = await self.app.push_screen_wait(
            PathPrompt("Load a mission from (YAML):", self.last_path or "", must_exist=True)
        )
        if not path:
            return
        from backend.files.diagnostics import FileProblems
        from backend.files.missions import load_mission

        try:
            mission, _lib = await asyncio.to_thread(load_mission, path)
        except FileProblems as e:
            first = str(e.issues[0]) if e.issues else str(e)
            more = f" (and {len(e.issues) - 1} more)" if len(e.issues) > 1 else ""
            self.say(f"cannot load: {first}{more}", "error")
            self.app.notify(first + more, title="Mission file invalid", severity="error")
            return
        except OSError as e:
            self.say(f"cannot load {path}: {e.strerror or e}", "error")
            return
        if not await self.app.push_screen_wait(
            ConfirmScreen(
                f"Replace the mission with {path} ('{mission.name}')? "
                "The current plan is replaced for every operator.",
                yes="Replace",
            )
        ):
            return
        self.last_path = path
        self.submit(
            LoadMission(mission=mission),
            f"load {path}",
            on_ok=lambda r: self.say(f"loaded {path}: '{mission.name}'", "ok"),
        )


def save_with_library(mission: Any, library: Any, path: Path) -> str:
    """Save the mission; if its library reference does not resolve from the
    new place, write the library beside it and point there."""
    from backend.files import yamlio
    from backend.files.missions import library_path, save_mission

    lib_file = library_path(path, mission.library)
    if lib_file.exists():
        save_mission(mission, path)
        return ""
    beside = path.with_name(path.stem + ".library.yaml")
    beside.write_text(
        yamlio.dump(
            library.model_dump(mode="json", exclude_defaults=True) | {"format": library.format}
        ),
        encoding="utf-8",
    )
    save_mission(mission, path, library_file=beside)
    return f"its skill library written to {beside.name}"
