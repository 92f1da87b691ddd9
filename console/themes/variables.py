"""The status colour variables every theme sets, and the default theme's name.

Every colour that carries meaning is a theme variable, so a theme file
(themes/*.yaml: dark, light, high-contrast, colour-blind-safe; loaded by
console/themes/loader.py) only has to set them. The defaults are declared in
`STATUS_DEFAULTS`, which the app returns from `get_theme_variable_defaults()`
so any theme (also Textual's own) parses.
Colours are picked to stay distinct in 256 colours (over SSH COLORTERM is
usually not forwarded); the status glyphs carry the meaning without colour.
"""

from __future__ import annotations

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

# The map (console/widgets/map/view.py): ground classes are cell backgrounds, the rest
# glyph colours; each also has a glyph or pattern, so colour is never alone.
# Defaults for every theme; a theme file may set them too (not required).
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

# what the app declares before any CSS is parsed (get_theme_variable_defaults)
VARIABLE_DEFAULTS: dict[str, str] = {**STATUS_DEFAULTS, **MAP_DEFAULTS}
