"""Theme files: themes/*.yaml (shipped) and <config dir>/themes/*.yaml (the user's).

A theme file is validated by `ThemeFile`: a name, dark or light, Textual's
base colours and every status/presence variable of `theme.STATUS_DEFAULTS`,
so a theme can never leave a status without its colour. A broken file is
skipped with a warning naming file:line (shown as a notification), never a
crash. A user theme with the name of a shipped one replaces it.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable
from functools import lru_cache
from pathlib import Path
from typing import Annotated

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)
from rich.color import STANDARD_PALETTE, ColorSystem
from rich.color import Color as RichColor
from rich.segment import Segment
from rich.style import Style
from textual.color import Color, ColorParseError
from textual.filter import LineFilter
from textual.theme import Theme

from backend.files import yamlio
from backend.files.diagnostics import pydantic_issues
from console.themes.variables import DEFAULT_THEME, STATUS_DEFAULTS


def _shipped_dir() -> Path:
    """The repository's themes/ (next to missions/, found the same way); a
    wheel install puts them in <prefix>/share/missionctl/themes (pyproject)."""
    repo = Path(__file__).resolve().parents[2] / "themes"
    installed = Path(sys.prefix) / "share" / "missionctl" / "themes"
    return repo if repo.is_dir() or not installed.is_dir() else installed


SHIPPED_DIR = _shipped_dir()

# in 16 colours statuses get colours of the standard ANSI palette, one each for
# the statuses that must not merge (the glyphs still carry the meaning)
ANSI16_STATUS: dict[str, str] = {
    "status-idle": "#aaaaaa",  # white
    "status-idle-synchronized": "#5555ff",  # bright blue
    "status-synchwaiting": "#aa5500",  # yellow (dark)
    "status-running": "#55ffff",  # bright cyan
    "status-paused": "#ffff55",  # bright yellow
    "status-success": "#55ff55",  # bright green
    "status-failure": "#ff5555",  # bright red
    "presence-online": "#55ff55",
    "presence-offline": "#ff5555",
    "presence-unknown": "#555555",
    "battery-low": "#ffff55",
}

# ...and the map's ground the standard colours it keeps apart: explored ground
# is brown out of comms range and grey in it (as the blends of the 256-colour
# defaults look), unexplored and rock are black; their textures (dots, ~, ▴,
# console/widgets/map/view.py GROUND16) tell the classes on the same background apart
ANSI16_MAP: dict[str, str] = {
    "map-outside": "#000000",
    "map-unknown": "#000000",
    "map-free": "#aa5500",
    "map-sand": "#aa5500",
    "map-rock": "#000000",
    "map-link": "#555555",  # the legend's "in comms range" swatch: explored ground in range
}


def _colour(v: str) -> str:
    try:
        Color.parse(v)
    except ColorParseError:
        raise ValueError(f"'{v}' is not a colour (use #rrggbb or a colour name)") from None
    return v


Colour = Annotated[str, AfterValidator(_colour)]


class ThemeFile(BaseModel):
    """One theme file."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field(
        min_length=1, description="the name shown in the palette and given to --theme"
    )
    dark: bool = True
    primary: str
    secondary: str | None = None
    accent: str | None = None
    warning: str | None = None
    error: str | None = None
    success: str | None = None
    foreground: str | None = None
    background: str | None = None
    surface: str | None = None
    panel: str | None = None
    variables: dict[str, Colour] = Field(description="every key of STATUS_DEFAULTS, plus any extra")

    @field_validator(
        "primary",
        "secondary",
        "accent",
        "warning",
        "error",
        "success",
        "foreground",
        "background",
        "surface",
        "panel",
    )
    @classmethod
    def _is_colour(cls, v: str | None) -> str | None:
        return None if v is None else _colour(v)

    @model_validator(mode="after")
    def _complete(self) -> ThemeFile:
        missing = [k for k in STATUS_DEFAULTS if k not in self.variables]
        if missing:
            raise ValueError(
                f"variables: missing {', '.join(missing)} "
                "(every status/presence colour must be set)"
            )
        return self

    def to_theme(self) -> Theme:
        base = self.model_dump(exclude={"variables"}, exclude_none=True)
        return Theme(**base, variables=dict(self.variables))


def user_dir() -> Path:
    base = Path(os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config") / "missionctl"
    return base / "themes"


def load_theme_file(path: Path) -> tuple[Theme | None, list[str]]:
    """(the theme, []) or (None, ["file:line: what is wrong"])."""
    file = str(path)
    try:
        doc = yamlio.load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as e:
        return None, [f"{file}: cannot read it ({e}); theme skipped"]
    except yamlio.YamlSyntaxError as e:
        return None, [f"{file}:{e.line}: {e.message}; theme skipped"]
    if not isinstance(doc.data, dict):
        return None, [
            f"{file}:1: expected a mapping (name, dark, primary, …, variables); theme skipped"
        ]
    try:
        tf = ThemeFile.model_validate(doc.data)
    except ValidationError as e:
        issues = pydantic_issues(file, doc, e)
        return None, [f"{i}; theme skipped" for i in issues]
    return tf.to_theme(), []


def load_themes(dirs: list[Path] | None = None) -> tuple[dict[str, Theme], list[str]]:
    """All themes of the shipped and the user's folders, later folders winning."""
    themes: dict[str, Theme] = {}
    problems: list[str] = []
    for d in dirs if dirs is not None else [SHIPPED_DIR, user_dir()]:
        if not d.is_dir():
            continue
        for path in sorted(d.glob("*.y*ml")):
            theme, issues = load_theme_file(path)
            problems.extend(issues)
            if theme is not None:
                themes[theme.name] = theme
    return themes, problems


def choose_theme(wanted: str | None, available: Iterable[str]) -> tuple[str, str | None]:
    """(the theme to use, a notice when the wanted one does not exist): the
    default is missionctl-dark, or Textual's own dark theme without it."""
    names = set(available)
    default = DEFAULT_THEME if DEFAULT_THEME in names else "textual-dark"
    wanted = wanted or default
    if wanted in names:
        return wanted, None
    return (
        default,
        f"unknown theme '{wanted}' (themes: {', '.join(sorted(names))}); using {default}",
    )


@lru_cache(maxsize=1024)
def _to16(color: RichColor | None) -> RichColor | None:
    if color is None or color.is_default or color.triplet is None and color.number is None:
        return color
    n = color.downgrade(ColorSystem.STANDARD).number
    return color if n is None else RichColor.from_triplet(STANDARD_PALETTE[n])


@lru_cache(maxsize=1024)
def _style16(style: Style) -> Style:
    return style + Style.from_color(_to16(style.color), _to16(style.bgcolor))


class Downgrade16(LineFilter):
    """Renders with the 16 standard colours, like a TERM=xterm terminal does,
    so a snapshot shows what such a terminal shows (and the app can check it)."""

    def apply(self, segments: list[Segment], background: Color) -> list[Segment]:
        return [
            Segment(s.text, _style16(s.style), s.control) if s.style is not None else s
            for s in segments
        ]
