"""The user's console settings: ~/.config/missionctl/config.toml (or .yaml).

    theme = "missionctl-dark"
    [keymap]
    "mission.sync" = "S"          # binding id -> key(s), comma separated
    "mission.delete" = "d,ctrl+d"

`MISSIONCTL_CONFIG` or `--config` point elsewhere. A broken file never stops
the console: its problems are shown as a notification and defaults apply.
A theme picked in the command palette is written back (`save_theme`), the
rest of the file kept.
"""

from __future__ import annotations

import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from backend.files import yamlio


@dataclass
class ConsoleConfig:
    theme: str | None = None
    keymap: dict[str, str] = field(default_factory=dict)
    path: Path | None = None
    problems: list[str] = field(default_factory=list)
    # where the recent files are remembered (None: only while the console runs)
    recent_path: Path | None = None


def state_dir() -> Path:
    """Where the console remembers things between runs (recent files):
    $XDG_STATE_HOME/missionctl, else ~/.local/state/missionctl."""
    base = os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state"
    return Path(base) / "missionctl"


def default_path() -> Path:
    env = os.environ.get("MISSIONCTL_CONFIG")
    if env:
        return Path(env)
    base = Path(os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config") / "missionctl"
    for name in ("config.toml", "config.yaml", "config.yml"):
        if (base / name).exists():
            return base / name
    return base / "config.toml"


def load_config(path: str | Path | None = None, known_ids: set[str] | None = None) -> ConsoleConfig:
    p = Path(path) if path else default_path()
    cfg = ConsoleConfig(path=p, recent_path=state_dir() / "recent.json")
    data = _settings(p, cfg, asked=bool(path))
    if data is None:
        return cfg
    theme = data.get("theme")
    if theme is not None:
        if isinstance(theme, str):
            cfg.theme = theme
        else:
            cfg.problems.append(f"{p}: theme: expected a theme name")
    _take_keymap(p, data.get("keymap", {}), cfg, known_ids)
    for key in data:
        if key not in ("theme", "keymap"):
            cfg.problems.append(f"{p}: unknown setting '{key}' (settings: theme, keymap)")
    return cfg


def _settings(p: Path, cfg: ConsoleConfig, asked: bool) -> dict[str, Any] | None:
    """The file's table of settings; None (the problem noted in `cfg`) when
    there is none to use (no file is no problem unless one was `asked` for)."""
    if not p.exists():
        if asked:
            cfg.problems.append(f"{p}: no such file; using defaults")
        return None
    try:
        text = p.read_text(encoding="utf-8")
        data = tomllib.loads(text) if p.suffix == ".toml" else yamlio.load(text).data or {}
    except yamlio.YamlSyntaxError as e:
        cfg.problems.append(f"{p}:{e.line}: cannot read it ({e.message}); using defaults")
        return None
    except (OSError, tomllib.TOMLDecodeError) as e:
        cfg.problems.append(f"{p}: cannot read it ({str(e).splitlines()[0]}); using defaults")
        return None
    if not isinstance(data, dict):
        cfg.problems.append(f"{p}: expected a table of settings; using defaults")
        return None
    return data


def _take_keymap(p: Path, keymap: Any, cfg: ConsoleConfig, known_ids: set[str] | None) -> None:
    """The [keymap] table's bindings into `cfg`, the broken ones as problems."""
    if not isinstance(keymap, dict):
        cfg.problems.append(f"{p}: keymap: expected a table of binding id = key")
        return
    for bid, keys in keymap.items():
        problem = _binding_problem(p, bid, keys, known_ids)
        if problem is None:
            cfg.keymap[bid] = keys
        else:
            cfg.problems.append(problem)


def _binding_problem(p: Path, bid: str, keys: Any, known_ids: set[str] | None) -> str | None:
    if not isinstance(keys, str) or not keys.strip():
        return f'{p}: keymap.{bid}: expected keys as a string, like "ctrl+s"'
    if known_ids is not None and bid not in known_ids:
        return f"{p}: keymap: unknown binding id '{bid}' (ids: {', '.join(sorted(known_ids))})"
    return None


def save_theme(path: Path, theme: str) -> str | None:
    """Remember the theme picked in the palette; keeps the rest of the file.
    Returns a problem sentence, or None when saved."""
    try:
        text = path.read_text(encoding="utf-8") if path.exists() else ""
        if path.suffix == ".toml":
            new = _toml_with_theme(text, theme)
        else:
            data = yamlio.load(text).data or {} if text else {}
            if not isinstance(data, dict):
                return f"{path}: expected a table of settings; theme not saved"
            data["theme"] = theme
            new = yaml.safe_dump(data, sort_keys=False)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(new, encoding="utf-8")
    except yamlio.YamlSyntaxError as e:
        return f"{path}:{e.line}: cannot save the theme ({e.message})"
    except (OSError, tomllib.TOMLDecodeError, yaml.YAMLError) as e:
        return f"{path}: cannot save the theme ({str(e).splitlines()[0]})"
    return None


def _toml_with_theme(text: str, theme: str) -> str:
    """The TOML `text` with its top-level theme set, the rest kept
    (TOMLDecodeError when the result would not read back)."""
    line = f'theme = "{theme}"'
    lines = text.splitlines()
    # top-level keys come before the first [table]
    end = next((i for i, x in enumerate(lines) if x.lstrip().startswith("[")), len(lines))
    for i in range(end):
        if re.match(r"\s*theme\s*=", lines[i]):
            lines[i] = line
            break
    else:
        lines.insert(0, line)
    new = "\n".join(lines) + "\n"
    tomllib.loads(new)  # never write a file we could not read back
    return new
