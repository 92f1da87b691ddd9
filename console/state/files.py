"""Files an operator saves and loads: where a save goes by default, what a
save would overwrite, path completion and the recent files (no Textual here).

A file is never overwritten without asking, and nothing is written into the
shipped example folder (`missions/` of this installation) without asking:
`save_risks` says what a save would do that needs a yes. Recent files are
remembered in a small JSON file (the config's `recent_path`; none: in memory).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from datetime import datetime
from pathlib import Path

# the example missions shipped with missionctl (the demo runs one of them)
SHIPPED_MISSIONS = Path(__file__).resolve().parents[2] / "missions"
RECENT_LIMIT = 10
COMPLETION_LIMIT = 200  # entries of a folder looked at for completions


def full_path(text: str, cwd: Path | None = None) -> Path:
    """What a typed path means: `~` expanded, relative to `cwd`, absolute."""
    p = Path(text.strip()).expanduser()
    if not p.is_absolute():
        p = (cwd or Path.cwd()) / p
    return Path(os.path.normpath(p))


def shown_path(p: Path) -> str:
    """A full path as shown to a person: the home folder as `~`."""
    home = Path.home()
    try:
        return "~/" + str(p.relative_to(home))
    except ValueError:
        return str(p)


def is_shipped(p: Path) -> bool:
    """Inside the example folder shipped with missionctl."""
    try:
        p.resolve().relative_to(SHIPPED_MISSIONS.resolve())
        return True
    except (ValueError, OSError):
        return False


def default_save_path(name: str, last: str | None, recent: list[str], cwd: Path) -> Path:
    """Where a save goes unless the operator types otherwise: the last file
    saved or loaded; else a file named after the mission in the folder of the
    most recent file, or the working folder — never the shipped examples'
    folder (then the home folder)."""
    if last:
        return full_path(last, cwd)
    stem = _file_stem(name)
    folder = Path(recent[0]).parent if recent else cwd
    if is_shipped(folder / "x"):
        folder = Path.home()
    return folder / f"{stem}.yaml"


def _file_stem(name: str) -> str:
    """A mission's name as a file's: lower case, letters, digits, - and _ kept,
    any other character _ ("mission" for no name)."""
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name.lower()) or "mission"


def _describe(p: Path) -> str:
    try:
        st = p.stat()
    except OSError:
        return shown_path(p)
    when = datetime.fromtimestamp(st.st_mtime).strftime("%Y-%m-%d %H:%M")
    return f"{shown_path(p)} ({st.st_size:,} bytes, changed {when})"


def save_risks(path: Path, also_written: list[Path] | None = None) -> list[str]:
    """What writing `path` (and `also_written`) would do that needs a yes:
    files that exist and would be replaced, the shipped examples' folder."""
    written = [path, *(also_written or [])]
    risks = [risk for p in written if (risk := _in_the_way(p))]
    if any(is_shipped(p) for p in written):
        risks.append(
            f"{shown_path(path.parent)} holds the examples shipped with missionctl"
            " (the demo starts from them)"
        )
    return risks


def _in_the_way(p: Path) -> str:
    """What is at `p` already ('' when nothing): a folder, or a file a write replaces."""
    if p.is_dir():
        return f"{shown_path(p)} is a folder"
    return f"{_describe(p)} exists and would be replaced" if p.exists() else ""


def path_note(
    text: str, *, must_exist: bool, cwd: Path | None = None, complete: str = ""
) -> tuple[str, str]:
    """(what the typed path means, severity) for the line under the input:
    the full path, and whether it is new, exists, or cannot be used
    (`complete`: the key that completes a path, in words)."""
    by = f" ({complete} completes)" if complete else ""
    if not text.strip():
        return f"type a file path{by}", "hint"
    p = full_path(text, cwd)
    where = shown_path(p)
    if p.is_dir():
        lists = f" ({complete} lists it)" if complete else ""
        return f"{where}/ is a folder: add a file name{lists}", "warning"
    if must_exist:
        return (where, "ok") if p.is_file() else (f"{where}: no such file", "warning")
    return _new_path_note(p, where)


def _new_path_note(p: Path, where: str) -> tuple[str, str]:
    """A path to write: whether its folder exists, it would replace a file or
    write into the shipped examples."""
    if not p.parent.is_dir():
        return f"{where}: the folder {shown_path(p.parent)} does not exist", "warning"
    if p.exists():
        return f"{where} exists: you will be asked before it is replaced", "warning"
    if is_shipped(p):
        return f"{where}: the shipped examples' folder (you will be asked)", "warning"
    return f"{where} (new file)", "ok"


def completions(text: str, cwd: Path | None = None, suffixes: tuple[str, ...] = ()) -> list[str]:
    """Completions of a typed path (as typed: `~` kept): the entries of its
    folder that start with its last part, folders ending in `/`; with
    `suffixes`, only files ending so (and folders)."""
    raw = text.strip() or "./"
    head, sep, tail = raw.rpartition("/")
    folder_text = head + sep
    folder = full_path(folder_text or ".", cwd)
    try:
        entries = sorted(folder.iterdir(), key=lambda e: e.name)[:COMPLETION_LIMIT]
    except OSError:
        return []
    out = []
    for e in entries:
        kind = _entry_kind(e, tail, suffixes)
        if kind is not None:
            out.append(folder_text + e.name + kind)
    return out


def _completes(name: str, tail: str) -> bool:
    """`name` starts with `tail`; a hidden one only when `tail` asks for it."""
    return name.startswith(tail) and (not name.startswith(".") or tail.startswith("."))


def _entry_kind(e: Path, tail: str, suffixes: tuple[str, ...]) -> str | None:
    """'/' for a folder, '' for a file, None when the entry does not complete
    `tail` (another start, hidden unless asked for, a file of another suffix)."""
    if not _completes(e.name, tail):
        return None
    try:
        is_dir = e.is_dir()
    except OSError:
        return None
    if is_dir:
        return "/"
    return "" if not suffixes or e.name.endswith(suffixes) else None


def complete(text: str, cwd: Path | None = None, suffixes: tuple[str, ...] = ()) -> str:
    """Tab: the longest common start of the completions (the one, if one)."""
    found = completions(text, cwd, suffixes)
    if not found:
        return text
    return os.path.commonprefix(found) or text


class RecentFiles:
    """The last files saved or loaded, newest first; kept in `path` (JSON)
    when given. A file that cannot be read or written is never an error:
    the list just starts empty or is not remembered."""

    def __init__(self, path: Path | None = None, limit: int = RECENT_LIMIT) -> None:
        self.path = path
        self.limit = limit
        self.files: list[str] = []
        if path is not None:
            try:
                data = json.loads(path.read_text(encoding="utf-8"))
                self.files = [str(x) for x in data if isinstance(x, str)][:limit]
            except (OSError, ValueError, TypeError):
                self.files = []

    def add(self, p: Path | str) -> None:
        text = str(p)
        self.files = [text, *(f for f in self.files if f != text)][: self.limit]
        if self.path is not None:
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self.path.write_text(json.dumps(self.files, indent=1), encoding="utf-8")
            except OSError:
                pass

    def existing(self, keep: Callable[[Path], bool] = Path.is_file) -> list[str]:
        return [f for f in self.files if keep(Path(f))]
