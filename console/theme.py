"""The console's default theme and its status colour variables.

Every colour that carries meaning is a theme variable, so a theme file (part
2: themes/*.yaml, light, high-contrast, colour-blind-safe) only has to set
them. The defaults are declared in `STATUS_DEFAULTS`, which the app returns
from `get_theme_variable_defaults()` so any theme (also Textual's own) parses.
Colours are picked to stay distinct in 256 colours (over SSH COLORTERM is
usually not forwarded); the status glyphs carry the meaning without colour.
"""

from __future__ import annotations

from textual.theme import Theme

DEFAULT_THEME = "missionctl-dark"

STATUS_DEFAULTS: dict[str, str] = {
    "status-idle": "#a8b0bc",
    "status-idle-synchronized": "#5fafff",
    "status-synchwaiting": "#d7af5f",
    "status-running": "#5fd7ff",
    "status-paused": "#ffaf00",
    "status-success": "#5fd75f",
    "status-failure": "#ff5f5f",
    "presence-online": "#5fd75f",
    "presence-offline": "#ff5f5f",
    "presence-unknown": "#8a8a8a",
    "barrier-tag": "#d787ff",
    "mark": "#ffd700",
    "divider": "#5f6b7a",
    "progress-bar": "#5fd7ff",
    "battery-low": "#ff8700",
}

# The map (console/mapview.py): ground classes are cell backgrounds, the rest
# glyph colours; each also has a glyph or pattern, so colour is never alone.
MAP_DEFAULTS: dict[str, str] = {
    "map-outside": "#0b0f14",
    "map-unknown": "#262a30",
    "map-free": "#6b5240",
    "map-sand": "#8f7548",
    "map-rock": "#3d3430",
    "map-link": "#2e6f9e",  # coverage: blended into the ground colour
    "map-lander": "#ffffff",
    "map-box": "#d7d7af",
    "map-rss": "#d787ff",
    "map-stone": "#ffd700",
    "map-marker-unused": "#a8b0bc",
    "map-marker-bound": "#87d7ff",
    "map-marker-active": "#ff8700",
    "map-goal": "#87ffaf",
    "map-cursor": "#ffff5f",
    "map-label": "#eeeeee",
}
STATUS_DEFAULTS.update(MAP_DEFAULTS)

MISSIONCTL_DARK = Theme(
    name=DEFAULT_THEME,
    primary="#3a7bd5",
    secondary="#5f87af",
    accent="#d787ff",
    warning="#ffaf00",
    error="#ff5f5f",
    success="#5fd75f",
    foreground="#dde3ea",
    background="#121820",
    surface="#1a222c",
    panel="#24303c",
    dark=True,
    variables=dict(STATUS_DEFAULTS),
)
