"""Mission and library files: load, check, save.

Every problem is an `Issue` with the file, the field path and, once resolved
against the YAML, the line and column. Loading never raises for bad input: it
returns every issue of the file at once.
"""

from __future__ import annotations

import copy
import os
from pathlib import Path as FsPath
from typing import Any, Literal, NamedTuple, TypeVar

from pydantic import BaseModel, ValidationError

from backend.core.bulk import gc_paused
from backend.core.checks import check_library, check_mission, resolve_shorthands
from backend.core.library import LIBRARY_FORMAT, Library
from backend.core.limits import LIMITS, too_big
from backend.core.model import (
    MISSION_FORMAT,
    Mission,
    Status,
)
from backend.files import yamlio
from backend.files.diagnostics import (
    FileProblems,
    Issue,
    Path,
    duplicate_issues,
    located,
    pydantic_issues,
)

M = TypeVar("M", bound=BaseModel)  # a file format's model


def read_yaml(path: FsPath) -> tuple[str, yamlio.YamlDoc]:
    file = str(path)
    text = _read_text(path, file)
    try:
        doc = yamlio.load(text)
    except yamlio.YamlSyntaxError as e:
        raise FileProblems(
            [Issue(file, path, message, line, col) for line, col, message, path in e.problems]
        ) from None
    if not isinstance(doc.data, dict):
        raise FileProblems(
            [Issue(file, (), "expected a YAML mapping at the top of the file", 1, 1)]
        )
    return file, doc


def _read_text(path: FsPath, file: str) -> str:
    """The file's text, or FileProblems saying why it cannot be read."""
    try:
        size = path.stat().st_size
        if size > LIMITS.file and path.is_file():  # not read: it could be anything
            message = too_big(size, LIMITS.file, "a file")
            raise FileProblems([Issue(file, (), f"{message}; missionctl reads no larger ones")])
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileProblems([Issue(file, (), "no such file")]) from None
    except IsADirectoryError:
        raise FileProblems([Issue(file, (), "is a directory, not a file")]) from None
    except UnicodeDecodeError as e:
        raise FileProblems(
            [Issue(file, (), f"not UTF-8 text ({e.reason} at byte {e.start})")]
        ) from None
    except OSError as e:
        raise FileProblems([Issue(file, (), f"cannot read: {e.strerror}")]) from None
    return text


# what tells a file's kind: its format's prefix (a wrong version is reported
# by the model), else a field only that kind has
_KINDS = (
    ("mission", "missionctl/mission", ("tasks", "robots")),
    ("library", "missionctl/library", ("robot_types", "skills")),
)


def file_kind(data: dict[str, Any]) -> str | None:
    fmt = data.get("format")
    if isinstance(fmt, str):
        return next((kind for kind, prefix, _ in _KINDS if fmt.startswith(prefix)), None)
    return next((kind for kind, _, fields in _KINDS if any(f in data for f in fields)), None)


# fields only one kind of file has
_FIELDS = {
    "mission": ("library", "robots", "markers", "tasks", "barriers"),
    "library": ("robot_types", "skills"),
}
_FORMATS = {"mission": MISSION_FORMAT, "library": LIBRARY_FORMAT}
_NAMES = {"mission": "a mission", "library": "a skill library"}


def _format_problem(file: str, doc: yamlio.YamlDoc, expected: str) -> FileProblems | None:
    """A file read as the `expected` kind whose `format` names another kind,
    or names one kind over the other's fields: one problem, said the same
    whichever command reads the file (`validate` goes by the format; `server`
    and `ctl load` expect a mission)."""
    fmt = doc.data.get("format")
    said = file_kind({"format": fmt}) if isinstance(fmt, str) else None
    if said is None:
        return None  # no format, or another one: the model says which it expects
    content, fields = _own_fields(doc.data)
    if content is not None and content != said:
        message = (
            f"{fmt!r} is the format of {_NAMES[said]}, but this file has the fields of "
            f"{_NAMES[content]} ({', '.join(fields)}): set 'format: {_FORMATS[content]}'"
        )
    elif said != expected:
        message = f"this is {_NAMES[said]} ({fmt!r}), not {_NAMES[expected]}"
    else:
        return None
    return FileProblems([located(file, doc, ("format",), message)])


def _own_fields(data: dict[str, Any]) -> tuple[str | None, list[str]]:
    """The one kind of file whose own fields `data` has, and those fields
    (None: it has the fields of neither kind, or of both)."""
    has = {kind: [f for f in fields if f in data] for kind, fields in _FIELDS.items()}
    kinds = [kind for kind, fields in has.items() if fields]
    return (kinds[0], has[kinds[0]]) if len(kinds) == 1 else (None, [])


def load_library(path: str | FsPath) -> Library:
    file, doc = read_yaml(FsPath(path))
    return _library_from(file, doc)


def _validated(
    model: type[M], file: str, doc: yamlio.YamlDoc, salvage: _Salvage
) -> tuple[M, list[Issue]]:
    """Validate the structure; on errors, validate what is left without the
    broken entries so one run reports every problem of the file."""
    issues = duplicate_issues(file, doc)
    try:
        return model.model_validate(doc.data), issues
    except ValidationError as e:
        issues += pydantic_issues(file, doc, e)
    try:
        return model.model_validate(salvage.without([i.path for i in issues])), issues
    except (ValidationError, _Unsalvageable):
        raise FileProblems(_sorted(issues)) from None


def _sorted(issues: list[Issue]) -> list[Issue]:
    return sorted(issues, key=lambda i: (i.file, i.line, i.col))


def _library_from(file: str, doc: yamlio.YamlDoc) -> Library:
    if (wrong := _format_problem(file, doc, "library")) is not None:
        raise wrong
    salvage = _Salvage(
        doc.data,
        entries=(("skills",), ("skills", "*", "params"), ("robot_types",)),
        required=("format",),
    )
    lib, issues = _validated(Library, file, doc, salvage)
    for path, msg in check_library(lib):
        if not salvage.explains(msg):
            issues.append(located(file, doc, path, msg))
    if issues:
        raise FileProblems(_sorted(issues))
    return lib


def library_path(mission_file: str | FsPath, library: str) -> FsPath:
    return (FsPath(mission_file).parent / library).resolve()


def load_mission(path: str | FsPath) -> tuple[Mission, Library]:
    with gc_paused():
        file, doc = read_yaml(FsPath(path))
        return _mission_from(file, doc)


def _mission_from(file: str, doc: yamlio.YamlDoc) -> tuple[Mission, Library]:
    if (wrong := _format_problem(file, doc, "mission")) is not None:
        raise wrong
    salvage = _Salvage(
        doc.data, entries=(("markers",), ("robots",), ("barriers",)), required=("format", "library")
    )
    m, issues = _validated(Mission, file, doc, salvage)
    lib = _library_of(file, doc, m, issues)
    resolve_shorthands(m, lib)
    for path, msg in check_mission(m, lib):
        if not salvage.explains(msg):
            issues.append(located(file, doc, _written_at(salvage, doc, path), msg))
    if issues:
        raise FileProblems(_sorted(issues))
    _fill_counters(m)
    return m, lib


def _library_of(file: str, doc: yamlio.YamlDoc, m: Mission, issues: list[Issue]) -> Library:
    """The library the mission names; when it cannot be loaded, FileProblems
    with the mission's `issues`, one saying so, then the library's."""
    try:
        return load_library(library_path(file, m.library))
    except FileProblems as e:
        head = located(
            file,
            doc,
            ("library",),
            f"library '{m.library}' cannot be loaded ({len(e.issues)} problem(s) listed below)",
        )
        raise FileProblems([*_sorted([*issues, head]), *e.issues]) from None


def _written_at(salvage: _Salvage, doc: yamlio.YamlDoc, path: Path) -> Path:
    """Where in the file the model's `path` was written: a task item at its
    index before the salvage, a marker binding under params ("@MARKER")."""
    path = salvage.original(path)
    if len(path) > 4 and path[3] == "bindings" and (*path[:3], "params", path[4]) in doc.marks:
        return (*path[:3], "params", *path[4:])
    return path


class _Unsalvageable(Exception):
    pass


class _Salvage:
    """A copy of a file's data without its broken entries, remembering what was
    dropped (to not report it twice) and where the kept task items were."""

    def __init__(
        self, data: Any, *, entries: tuple[tuple[str, ...], ...], required: tuple[str, ...]
    ):
        self.data = data
        self.entries = entries  # mappings whose broken entries can be dropped
        self.required = required  # top-level fields that cannot be left out
        self.dropped: set[str] = set()
        self.kept: dict[str, list[int]] = {}

    def without(self, paths: list[Path]) -> dict[Any, Any]:
        data: dict[Any, Any] = copy.deepcopy(self.data)
        drop_items: dict[str, set[int]] = {}  # robot -> indices of its broken task items
        for p in paths:
            self._drop(data, p, drop_items)
        for robot, idx in drop_items.items():
            self._drop_items(data, robot, idx)
        return data

    def _drop(self, data: dict[Any, Any], p: Path, drop_items: dict[str, set[int]]) -> None:
        """Drop what the broken path `p` is in (task items: noted in
        `drop_items`, dropped after, as their indices are the paths'), or
        raise _Unsalvageable."""
        if not p or (len(p) == 1 and p[0] in self.required):
            raise _Unsalvageable(p)
        if len(p) == 1:
            data.pop(p[0], None)  # an unknown or broken optional field
        elif (where := self._entry(data, p)) is not None:
            container, name = where
            container.pop(name, None)
            self.dropped.add(str(name))
        elif p[0] == "tasks":
            self._drop_task(data, p, drop_items)
        else:
            raise _Unsalvageable(p)

    def _drop_task(self, data: dict[Any, Any], p: Path, drop_items: dict[str, set[int]]) -> None:
        if len(p) >= 3 and isinstance(p[2], int):
            drop_items.setdefault(str(p[1]), set()).add(p[2])
        elif isinstance(data.get("tasks"), dict):
            data["tasks"].pop(p[1], None)
            self.dropped.add(str(p[1]))
        else:
            raise _Unsalvageable(p)

    def _drop_items(self, data: dict[Any, Any], robot: str, idx: set[int]) -> None:
        """Drop task items `idx` of `robot`, remembering their ids and where
        the kept ones were."""
        items = data["tasks"][robot]
        for i in idx:
            if isinstance(items[i], dict) and isinstance(items[i].get("id"), str):
                self.dropped.add(items[i]["id"])
        self.kept[robot] = [i for i in range(len(items)) if i not in idx]
        data["tasks"][robot] = [items[i] for i in self.kept[robot]]

    def _entry(self, data: Any, p: Path) -> tuple[dict[Any, Any], Any] | None:
        """The mapping holding the deepest droppable entry on path `p`."""
        for pattern in sorted(self.entries, key=len, reverse=True):
            if _below(pattern, p) and isinstance(cur := _at(data, p[: len(pattern)]), dict):
                return cur, p[len(pattern)]
        return None

    def explains(self, message: str) -> bool:
        """A reference to a dropped entry was reported through that entry."""
        return any(
            f"unknown {what} '{name}'" in message or f"no skill '{name}'" in message
            for name in self.dropped
            for what in ("skill", "skill id", "marker", "robot", "robot type")
        ) or any(f"tasks for unknown robot '{name}'" in message for name in self.dropped)

    def original(self, path: Path) -> Path:
        if (
            len(path) >= 3
            and path[0] == "tasks"
            and isinstance(path[2], int)
            and path[1] in self.kept
        ):
            return (*path[:2], self.kept[path[1]][path[2]], *path[3:])
        return path


def _below(pattern: tuple[str, ...], p: Path) -> bool:
    """Path `p` leads below `pattern` ("*": any segment)."""
    return len(p) > len(pattern) and all(
        a == "*" or a == b for a, b in zip(pattern, p, strict=False)
    )


def _at(data: Any, path: Path) -> Any:
    """The value at `path` in `data`, None when there is none."""
    for seg in path:
        data = data.get(seg) if isinstance(data, dict) else None
    return data


def _fill_counters(m: Mission) -> None:
    """Keep generated ids clear of those already in the file."""
    for sid in m.all_ids():
        tail = sid.rsplit("-", 1)[-1]
        if tail.isdigit():
            m.next_skill = max(m.next_skill, int(tail) + 1)
    for bid in m.barriers:
        if bid.startswith("b") and bid[1:].isdigit():
            m.next_barrier = max(m.next_barrier, int(bid[1:]) + 1)
    for robot in m.robots:
        m.tasks.setdefault(robot, [])


def validate_file(path: str | FsPath) -> list[Issue]:
    """All issues of one mission or library file (empty when valid)."""
    try:
        with gc_paused():
            file, doc = read_yaml(FsPath(path))
            kind = file_kind(doc.data)
            if kind == "library":
                _library_from(file, doc)
            elif kind == "mission":
                _mission_from(file, doc)
            else:
                return [
                    Issue(
                        file,
                        ("format",),
                        f"not a missionctl file: set 'format: {MISSION_FORMAT}' "
                        f"or 'format: {LIBRARY_FORMAT}'",
                        *doc.mark(("format",)),
                    )
                ]
    except FileProblems as e:
        return e.issues
    return []


# -- saving -------------------------------------------------------------------


_SKILL_DEFAULTS = {
    "label": "",
    "bindings": {},
    "status": "idle",
    "status_info": "",
    "attempt": 1,
    "started_at": None,
    "finished_at": None,
    "policies": {"retries": 0, "pause_out_of_comms": False, "recharge_below": None},
    "rev": 0,
}


def _drop(d: dict[str, Any], defaults: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in d.items() if not (k in defaults and v == defaults[k])}


def mission_to_data(m: Mission) -> dict[str, Any]:
    """Readable file content: stable key order, noise-free defaults left out."""
    data = m.model_dump(mode="json")
    data["robots"] = {n: _drop(r, {"description": ""}) for n, r in data["robots"].items()}
    data["markers"] = {n: _drop(mk, {"description": ""}) for n, mk in data["markers"].items()}
    data["tasks"] = {r: [_drop(s, _SKILL_DEFAULTS) for s in t] for r, t in data["tasks"].items()}
    return _drop(data, {**_bookkeeping(), "next_skill": 1, "next_barrier": 1, "barriers": {}})


def _bookkeeping() -> dict[str, Any]:
    """The server's bookkeeping a file leaves out: per-list revisions, the
    robots' sequence numbers, the uplink (fresh values each time)."""
    return {
        "task_revs": {},
        "marker_revs": {},
        "report_seqs": {},
        "uplink": {},
        "uplink_seqs": {},
        "next_command": 1,
    }


def mission_to_yaml(m: Mission) -> str:
    return yamlio.dump(mission_to_data(m))


# what a saved file holds: "state" (statuses and the log as they are) or
# "plan" (every skill idle, to run again)
SaveWhat = Literal["plan", "state"]


def as_file(m: Mission, what: SaveWhat = "state") -> Mission:
    """The mission as a file holds it: without the server's bookkeeping
    (`_bookkeeping`, and each skill's revision); as a plan, every skill
    idle (status, its information and times reset; attempts kept)."""
    reset = {"status": Status.IDLE, "status_info": "", "started_at": None, "finished_at": None}
    tasks = {
        r: [s.model_copy(update={"rev": 0, **(reset if what == "plan" else {})}) for s in t]
        for r, t in m.tasks.items()
    }
    return m.model_copy(update={"tasks": tasks, **_bookkeeping()})


def library_beside(m: Mission, library: Library, path: str | FsPath) -> FsPath | None:
    """The skill library file a save of `m` to `path` writes beside it
    (NAME.library.yaml), when the mission's library reference does not lead
    from there to `library`; None when it does."""
    p = FsPath(path)
    resolved = library_path(p, m.library)
    try:
        if resolved.is_file() and load_library(resolved) == library:
            return None
    except FileProblems:
        pass
    return p.with_name(p.stem + ".library.yaml")


def save_library(library: Library, path: str | FsPath) -> None:
    text = yamlio.dump(
        library.model_dump(mode="json", exclude_defaults=True) | {"format": library.format}
    )
    FsPath(path).write_text(text, encoding="utf-8")


class Saved(NamedTuple):
    library: str  # the reference the file holds, relative to its folder
    library_file: FsPath | None  # the library written beside it (None: none written)


def save_mission_file(
    m: Mission,
    library: Library,
    path: str | FsPath,
    what: SaveWhat = "state",
    library_file: str | FsPath | None = None,
) -> Saved:
    """Save `m` (`as_file`) so that the file loads from where it is: its
    library reference leads to `library_file` when given, else to the
    mission's library when that is `library`, else to `library` written
    beside it (`library_beside`). The way `ctl save` and the console save."""
    p = FsPath(path)
    written = None
    if library_file is None and (beside := library_beside(m, library, p)) is not None:
        save_library(library, beside)
        library_file = written = beside
    return Saved(save_mission(as_file(m, what), p, library_file), written)


def save_mission(m: Mission, path: str | FsPath, library_file: str | FsPath | None = None) -> str:
    """Write atomically (a crash mid-save never leaves half a file). With
    `library_file`, the library reference is rewritten relative to `path`.
    Returns the reference written. (`save_mission_file` makes a file of a
    live mission.)"""
    p = FsPath(path)
    if library_file is not None:
        rel = os.path.relpath(FsPath(library_file).resolve(), p.resolve().parent)
        m = m.model_copy(update={"library": rel})
    tmp = p.with_name(p.name + ".tmp")
    try:
        with gc_paused():  # the YAML is built from a dict of the whole mission
            text = mission_to_yaml(m)
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(p)
    except BaseException:
        tmp.unlink(missing_ok=True)  # a full disk leaves no half-written .tmp behind
        raise
    return m.library
