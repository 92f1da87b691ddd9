"""The map widget: the site in text cells, two square "pixels" per cell.

Each cell is a half-block: `▀` with the upper pixel as foreground colour and
the lower one as background (a space when both are equal). Ground pixels
come from the map feed's mirror (terrain class, coverage tint); shapes
(area markers, regions) are drawn as pixels too; points (lander, boxes,
stones, markers, goals, robots, the cursor) are glyphs with a label. Every
ground class also has a glyph pattern, and every point a distinct glyph, so
nothing depends on colour alone.

Rendering is the Line API (`render_line`) with a cache of rendered rows.
Overlays are recomputed as a dict row -> cells; a change (a robot moving, a
marker edited) dirties only the rows whose overlay cells differ, and a map
delta only the rows its tiles cover. Pan, zoom, resize and theme changes
redraw everything.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from rich.color import Color as RichColor
from rich.segment import Segment
from rich.style import Style
from textual import events
from textual.color import Color
from textual.geometry import Region
from textual.message import Message
from textual.strip import Strip
from textual.widget import Widget

from backend.core.model import FINISHED, Status
from backend.protocol.mapfeed import T_FREE, T_ROCK, T_SLOW, T_UNKNOWN, MapMirror
from console.state.contact import CONTACT_GLYPH, out_of_contact
from console.state.markers import marker_point, marker_use
from console.state.model import ConsoleModel
from console.state.nowcast import NOWCAST_GLYPH, robot_nowcast
from console.state.site import clamp_to_site
from console.state.text import GLYPHS, STATUS_CSS

UPPER_HALF = "▀"
OUTSIDE = 8  # ground class of pixels outside the map (0..7: terrain + 4 if covered)

# heading glyphs, counter-clockwise from east in 45° steps
ROBOT_ARROWS = "▶◥▲◤◀◣▼◢"
NOWCAST_ARROWS = "▷◹△◸◁◺▽◿"  # hollow: where a robot probably is now (≈, its now-cast)
POSE_ARROWS = "→↗↑↖←↙↓↘"
POSITION_GLYPH = "⊕"
AREA_GLYPH = "◇"
LANDER_GLYPH = "⌂"
BOX_GLYPH = "▣"
RSS_GLYPH = "◎"
STONE_GLYPH = "•"
GOAL_GLYPH = "×"
OFFLINE_GLYPH = "✕"
NO_LINK_GLYPH = "⊘"  # out of comms range
FOLLOW_GLYPH = "⊙"

GROUND_VARS = {T_UNKNOWN: "map-unknown", T_FREE: "map-free", T_SLOW: "map-sand", T_ROCK: "map-rock"}
COVERAGE_TINT = 0.35
# In 16 colours a blend or a lightened texture falls back onto the colour it
# came from: ground class -> (background in comms range, texture colour out
# of range, texture colour in range); out of range the background is the
# class's own variable (themes.ANSI16_MAP)
GROUND16 = {
    T_UNKNOWN: ("#000000", "#555555", "#5555ff"),
    T_FREE: ("#555555", "#555555", "#555555"),
    T_SLOW: ("#555555", "#ffff55", "#ffff55"),
    T_ROCK: ("#000000", "#aaaaaa", "#5555ff"),
}
MIN_MPP, MAX_MPP = 0.25, 64.0
WHEEL_ZOOM = 0.7  # scale per wheel step (in); the keys' + and - halve and double


def heading_glyph(yaw: float, glyphs: str) -> str:
    """One of 8 glyphs for a heading (radians, counter-clockwise from east)."""
    return glyphs[round(yaw / (math.pi / 4)) % 8]


# -- half-block rows (pure: unit-tested) -------------------------------------------------

_style_cache: dict[tuple[Any, Any, bool], Style] = {}


def _style(fg: RichColor | None, bg: RichColor | None, bold: bool = False) -> Style:
    key = (fg, bg, bold)
    st = _style_cache.get(key)
    if st is None:
        st = _style_cache[key] = Style(color=fg, bgcolor=bg, bold=bold or None)
    return st


Glyph = tuple[str, RichColor, bool, RichColor | None]  # char, colour, bold, background


def halfblock_row(
    top: Sequence[Any],
    bottom: Sequence[Any],
    colours: Mapping[Any, RichColor],
    glyphs: Mapping[int, Glyph] | None = None,
    pattern: Callable[[int, Any], str] | None = None,
    textures: Mapping[Any, RichColor] | None = None,
) -> list[Segment]:
    """Segments of one text row from its two pixel rows.

    `top[i]`/`bottom[i]` are colour keys of column i's upper and lower pixel;
    a glyph (char, colour, bold, background or None) replaces column i's
    half-block (by default on the upper pixel's colour); `pattern(i, key)`
    gives the character drawn where both pixels are equal (" " for none), in
    `textures[key]` (default: the key's colour, a little lighter). Runs of
    equal style are merged."""
    cells = HalfBlocks(colours, glyphs or {}, pattern or _no_pattern, textures or {})
    if len(top) != len(bottom):
        raise ValueError(f"pixel rows of {len(top)} and {len(bottom)} columns")
    return merged(map(cells.cell, range(len(top)), top, bottom))


def _no_pattern(i: int, key: Any) -> str:
    return " "


@dataclass(frozen=True)
class HalfBlocks:
    """How one text cell is drawn from its two pixels (halfblock_row says)."""

    colours: Mapping[Any, RichColor]
    glyphs: Mapping[int, Glyph]
    pattern: Callable[[int, Any], str]
    textures: Mapping[Any, RichColor]

    def cell(self, i: int, a: Any, b: Any) -> tuple[str, Style]:
        """Column i's character and style: its glyph, its ground's pattern, or a half-block."""
        g = self.glyphs.get(i)
        if g is not None:
            return g[0], _style(g[1], g[3] or self.colours[a], g[2])
        if a != b:
            return UPPER_HALF, _style(self.colours[a], self.colours[b])
        ch = self.pattern(i, a)
        fg = None if ch == " " else self.textures.get(a) or _pattern_fg(self.colours[a])
        return ch, _style(fg, self.colours[a])


def merged(cells: Iterable[tuple[str, Style]]) -> list[Segment]:
    """Segments of (character, style) cells, a run of one style in one segment."""
    segs: list[Segment] = []
    text: list[str] = []
    run: Style | None = None
    for ch, st in cells:
        if st is not run:
            if text:
                segs.append(Segment("".join(text), run))
            text, run = [], st
        text.append(ch)
    if text:
        segs.append(Segment("".join(text), run))
    return segs


_pattern_cache: dict[RichColor, RichColor] = {}


def _pattern_fg(bg: RichColor) -> RichColor:
    """A texture colour: the ground colour, a little lighter."""
    fg = _pattern_cache.get(bg)
    if fg is None:
        fg = _pattern_cache[bg] = Color.from_rich_color(bg).lighten(0.12).rich_color
    return fg


# -- the view's geometry ----------------------------------------------------------------------


@dataclass
class Viewport:
    """Centre (metres), metres per pixel, size in cells (pixels: w x 2h)."""

    cx: float = 0.0
    cy: float = 0.0
    mpp: float = 2.0
    w: int = 80
    h: int = 20

    def px_x(self, px: np.ndarray | int) -> Any:
        return self.cx + (px + 0.5 - self.w / 2) * self.mpp

    def py_y(self, py: int) -> float:
        return self.cy + (self.h - py - 0.5) * self.mpp

    def to_pixel(self, x: float, y: float) -> tuple[int, int]:
        return math.floor((x - self.cx) / self.mpp + self.w / 2), math.floor(
            self.h - (y - self.cy) / self.mpp
        )

    def to_cell(self, x: float, y: float) -> tuple[int, int]:
        px, py = self.to_pixel(x, y)
        return px, py // 2

    def cell_centre(self, col: int, row: int) -> tuple[float, float]:
        """World position of a cell's centre (between its two pixels)."""
        return float(self.px_x(col)), self.cy + (self.h - 2 * row - 1) * self.mpp


def ground_classes(
    mirror: MapMirror | None, vp: Viewport, py: int, xs_index: np.ndarray | None
) -> np.ndarray:
    """Ground class (0..7, OUTSIDE) of every pixel of pixel row `py`."""
    out = np.full(vp.w, OUTSIDE, dtype=np.int16)
    if mirror is None or mirror.meta is None or xs_index is None:
        return out
    m = mirror.meta
    iy = math.floor((vp.py_y(py) - m.y0) / m.cell)
    if not 0 <= iy < m.height:
        return out
    valid = (xs_index >= 0) & (xs_index < m.width)
    cols = xs_index[valid]
    terrain = mirror.layers["terrain"][iy, cols].astype(np.int16)
    cov = mirror.layers.get("coverage")
    if cov is not None:
        terrain = terrain + 4 * (cov[iy, cols] > 0)
    out[valid] = terrain
    return out


# -- overlays ---------------------------------------------------------------------------------

Cell = tuple[str, str, bool]  # glyph, colour variable, bold
CURSOR_FG = "map-outside"  # the cursor cell is drawn reversed: this on map-cursor


class Overlay:
    """Glyph cells (row -> col -> Cell) and shape pixels (py -> px -> colour variable)."""

    def __init__(self, vp: Viewport) -> None:
        self.vp = vp
        self.cells: dict[int, dict[int, Cell]] = {}
        self.pixels: dict[int, dict[int, str]] = {}
        self.where: dict[str, tuple[int, int]] = {}  # thing -> its cell (tests, clicks)
        self.strong: set[tuple[int, int]] = set()  # cells holding a glyph (labels never cover them)
        self._labels: list[tuple[int, int, str, str]] = []

    def put(
        self, col: int, row: int, ch: str, var: str, bold: bool = False, *, label: bool = False
    ) -> None:
        if 0 <= col < self.vp.w and 0 <= row < self.vp.h:
            if label and (col, row) in self.strong:
                return
            if not label:
                self.strong.add((col, row))
            self.cells.setdefault(row, {})[col] = (ch, var, bold)

    def point(
        self,
        key: str,
        x: float,
        y: float,
        ch: str,
        var: str,
        label: str = "",
        label_var: str = "map-label",
        bold: bool = True,
    ) -> None:
        col, row = self.vp.to_cell(x, y)
        self.where[key] = (col, row)
        self.put(col, row, ch, var, bold)
        if label:
            self._labels.append((col + 2, row, label, label_var))

    def place_labels(self) -> None:
        """Labels after all glyphs, the most important (drawn last) first.
        A label goes right of its glyph, else left, above or below, wherever
        it covers no glyph and no earlier label; else right, cut short."""
        for col, row, text, var in reversed(self._labels):
            c0, r0 = self._label_spot(col, row, len(text))
            taken = self.cells.get(r0, {})
            for i, c in enumerate(text):
                if c0 + i in taken:
                    break
                self.put(c0 + i, r0, c, var, label=True)
        self._labels.clear()

    def _label_spot(self, col: int, row: int, n: int) -> tuple[int, int]:
        """Where a label of `n` cells for the glyph left of (col, row) goes."""
        spots = [
            (col, row),
            (col - n - 3, row),
            (col - 2 - n // 2, row - 1),
            (col - 2 - n // 2, row + 1),
        ]
        return next((spot for spot in spots if self._free(*spot, n)), (col, row))

    def _free(self, c0: int, r0: int, n: int) -> bool:
        """Whether `n` cells from (c0, r0) are in the view and hold nothing yet."""
        inside = 0 <= r0 < self.vp.h and c0 >= 0 and c0 + n <= self.vp.w
        return inside and not any(c0 + i in self.cells.get(r0, {}) for i in range(n))

    def cursor(self, x: float, y: float, arrow: str) -> None:
        """The cursor: the glyph under it (or the heading arrow), reversed."""
        col, row = self.vp.to_cell(x, y)
        self.where["cursor"] = (col, row)
        under = self.cells.get(row, {}).get(col) if (col, row) in self.strong else None
        self.put(col, row, under[0] if under else arrow, CURSOR_FG, True)

    def pixel(self, px: int, py: int, var: str) -> None:
        if 0 <= px < self.vp.w and 0 <= py < 2 * self.vp.h:
            self.pixels.setdefault(py, {})[px] = var

    def line(
        self, a: tuple[float, float], b: tuple[float, float], var: str, every: int = 1
    ) -> None:
        """Pixels of a segment (every `every`-th: dotted), clipped to the view first
        (zoomed in, a long edge would otherwise cost a pixel step per metre off screen)."""
        clipped = clip_segment(self.vp.to_pixel(*a), self.vp.to_pixel(*b), self.vp.w, 2 * self.vp.h)
        if clipped is None:
            return
        (x0, y0), (x1, y1) = clipped
        n = max(abs(round(x1) - round(x0)), abs(round(y1) - round(y0)), 1)
        for k in range(0, n + 1, every):
            self.pixel(round(x0 + (x1 - x0) * k / n), round(y0 + (y1 - y0) * k / n), var)

    def polygon(self, pts: list[tuple[float, float]], var: str) -> None:
        for i, p in enumerate(pts):
            self.line(p, pts[(i + 1) % len(pts)], var)

    def circle(self, x: float, y: float, r: float, var: str) -> None:
        n = max(12, int(2 * math.pi * r / self.vp.mpp))
        if n > 2000:
            return
        pts = [
            (x + r * math.cos(2 * math.pi * k / n), y + r * math.sin(2 * math.pi * k / n))
            for k in range(n)
        ]
        for p in pts:
            px, py = self.vp.to_pixel(*p)
            self.pixel(px, py, var)

    def row_signature(self, row: int) -> tuple:
        return (
            tuple(sorted(self.cells.get(row, {}).items())),
            tuple(sorted(self.pixels.get(2 * row, {}).items())),
            tuple(sorted(self.pixels.get(2 * row + 1, {}).items())),
        )


def clip_segment(
    a: tuple[float, float], b: tuple[float, float], w: int, h: int
) -> tuple[tuple[float, float], tuple[float, float]] | None:
    """The part of segment a-b inside [-1, w] x [-1, h] (Liang-Barsky), or None."""
    (x0, y0), (x1, y1) = a, b
    dx, dy = x1 - x0, y1 - y0
    t0, t1 = 0.0, 1.0
    for p, q in ((-dx, x0 + 1), (dx, w - x0), (-dy, y0 + 1), (dy, h - y0)):
        if p == 0:
            if q < 0:
                return None
            continue
        t = q / p
        if p < 0:
            t0 = max(t0, t)
        else:
            t1 = min(t1, t)
        if t0 > t1:
            return None
    return (x0 + t0 * dx, y0 + t0 * dy), (x0 + t1 * dx, y0 + t1 * dy)


def marker_points(mk: Any) -> list[tuple[float, float]]:
    """A marker's points: a pose's or a position's, an area's corners."""
    if mk.kind == "area":
        return [(p.x, p.y) for p in mk.area]
    return [marker_point(mk)]


def explored_points(mirror: MapMirror | None) -> list[tuple[float, float]]:
    """The lander and the corners of the box around what is explored."""
    if mirror is None or mirror.meta is None:
        return []
    g = mirror.meta
    pts = [(mirror.objects.lander.x, mirror.objects.lander.y)] if mirror.objects else []
    rows, cols = np.nonzero(mirror.layers["terrain"] != T_UNKNOWN)
    if len(rows):
        pts += [
            (g.x0 + cols.min() * g.cell, g.y0 + rows.min() * g.cell),
            (g.x0 + (cols.max() + 1) * g.cell, g.y0 + (rows.max() + 1) * g.cell),
        ]
    return pts


def known_points(model: ConsoleModel, mirror: MapMirror | None) -> list[tuple[float, float]]:
    """What is known of the site: robots, markers, the lander, the explored area."""
    pts = [(t.pose.x, t.pose.y) for t in model.telemetry.values()]
    markers = model.mission.markers.values() if model.mission is not None else []
    return pts + [p for mk in markers for p in marker_points(mk)] + explored_points(mirror)


def robot_status(model: ConsoleModel, robot: str) -> tuple[str, str]:
    """(glyph, colour variable) of what a robot is doing, for its map label."""
    if not model.is_online(robot):
        return OFFLINE_GLYPH, "presence-offline"
    if out_of_contact(model.robots.get(robot)):  # drawn where it was last heard, dimmed
        return CONTACT_GLYPH, "presence-unknown"
    st = _doing(model, robot)
    return GLYPHS[st], f"status-{STATUS_CSS[st]}"


def _doing(model: ConsoleModel, robot: str) -> Status:
    """The status a robot's label shows: its acting skill's, else whether it waits."""
    act, queued = model.robot_state(robot)
    if act is not None:
        return act.status
    finished = [s for s in model.task(robot) if s.status in FINISHED]
    if finished and finished[-1].status == Status.FAILURE:
        return Status.FAILURE  # halted after a failure: the operator decides
    return Status.IDLE_SYNCHRONIZED if queued else Status.IDLE


MARKER_USE_GLYPH = {"active": " ●", "bound": " ○", "unused": ""}


def skill_goals(model: ConsoleModel) -> list[tuple[str, str, float, float, Status]]:
    """(robot, skill id, x, y, status) of the pose/position parameters of
    unfinished skills that are typed values (bound ones sit on their marker)."""
    m, lib = model.mission, model.library
    if m is None or lib is None:
        return []
    return [
        (robot, s.id, x, y, s.status)
        for robot, s, spec in _unfinished(m, lib)
        for x, y in typed_goals(s, spec)
    ]


def _unfinished(m: Any, lib: Any) -> Iterable[tuple[str, Any, Any]]:
    """(robot, skill, its spec) of every unfinished skill of the library's."""
    for robot, task in m.tasks.items():
        for s in task:
            spec = lib.skills.get(s.skill)
            if s.status not in FINISHED and spec is not None:
                yield robot, s, spec


def typed_goals(s: Any, spec: Any) -> list[tuple[float, float]]:
    """(x, y) of a skill's pose and position parameters given as typed values."""
    out = []
    for pname, p in spec.params.items():
        v = s.params.get(pname)
        if p.type in ("pose", "position") and pname not in s.bindings and _has_xy(v):
            out.append((float(v["x"]), float(v["y"])))
    return out


def _has_xy(v: Any) -> bool:
    return isinstance(v, dict) and "x" in v and "y" in v


# -- what the overlay shows (MapView._build_overlay draws them in this order) --


def draw_areas(ov: Overlay, mission: Any, use: dict[str, str]) -> None:
    """Area markers' outlines, coloured by use."""
    for name, mk in mission.markers.items():
        if mk.kind == "area":
            ov.polygon([(p.x, p.y) for p in mk.area], f"map-marker-{use.get(name, 'unused')}")


def draw_goals(ov: Overlay, model: ConsoleModel, selected_skill: str | None) -> None:
    """Typed pose/position parameters of unfinished skills (the selected one labelled)."""
    for _robot, sid, x, y, st in skill_goals(model):
        label = sid if sid == selected_skill else ""
        ov.point(f"goal:{sid}", x, y, GOAL_GLYPH, f"status-{STATUS_CSS[st]}", label, "map-goal")


def draw_objects(ov: Overlay, objects: Any) -> None:
    """The map feed's objects: lander, sampling regions, boxes on the ground, stones."""
    lander = objects.lander
    ov.point("lander", lander.x, lander.y, LANDER_GLYPH, "map-lander", "lander")
    for r in objects.rss:
        score = f" {r.top_score:g}" if r.top_score is not None else ""
        ov.point(f"rss:{r.rss}", r.x, r.y, RSS_GLYPH, "map-rss", r.rss + score, "map-rss")
    draw_boxes(ov, objects.boxes)
    draw_stones(ov, objects.stones)


def draw_boxes(ov: Overlay, boxes: Any) -> None:
    """The payload boxes on the ground (" on": switched on)."""
    for b in boxes:
        if b.where == "ground":
            label = b.box + (" on" if b.on else "")
            ov.point(f"box:{b.box}", b.x, b.y, BOX_GLYPH, "map-box", label, "map-box")


def draw_stones(ov: Overlay, stones: Any) -> None:
    """The stones found (identified, or left on the ground)."""
    for s in stones:
        if s.state in ("identified", "ground"):
            ov.point(f"stone:{s.id}", s.x, s.y, STONE_GLYPH, "map-stone")


def marker_glyph(mk: Any) -> str:
    if mk.kind == "pose":
        return heading_glyph(mk.pose.yaw, POSE_ARROWS)
    return POSITION_GLYPH if mk.kind == "position" else AREA_GLYPH


def draw_markers(ov: Overlay, mission: Any, use: dict[str, str], selected: str | None) -> None:
    """Every marker's glyph and name (with how it is used; [the selected one])."""
    for name, mk in mission.markers.items():
        var = f"map-marker-{use.get(name, 'unused')}"
        label = name + MARKER_USE_GLYPH[use.get(name, "unused")]
        if name == selected:
            label = f"[{label}]"
        x, y = marker_point(mk)
        ov.point(f"marker:{name}", x, y, marker_glyph(mk), var, label, var)


def draw_robots(ov: Overlay, model: ConsoleModel, follow: str | None) -> None:
    """Robots with telemetry: heading arrow, name, what they do, out of range, followed."""
    for robot in model.robot_order():
        if model.robot_kind(robot) == "static":
            continue  # the lander is drawn from the feed
        t = model.telemetry.get(robot)
        if t is None:
            continue
        glyph, var = robot_status(model, robot)
        arrow = heading_glyph(t.pose.yaw, ROBOT_ARROWS)
        name = (
            f"{robot} {glyph}"
            + (f" {NO_LINK_GLYPH}" if not t.in_range else "")
            + (f" {FOLLOW_GLYPH}" if follow == robot else "")
        )
        ov.point(f"robot:{robot}", t.pose.x, t.pose.y, arrow, var, name, var)
        draw_nowcast(ov, model, robot, t)


def draw_nowcast(ov: Overlay, model: ConsoleModel, robot: str, t: Any) -> None:
    """Where a robot last known is probably now: hollow, dotted from its last known place."""
    nc = robot_nowcast(model, robot)
    if nc is None or nc.x is None or nc.y is None:
        return
    if ov.vp.to_cell(nc.x, nc.y) == ov.where.get(f"robot:{robot}"):
        return  # where it was last known: nothing more to say
    ov.line((t.pose.x, t.pose.y), (nc.x, nc.y), "presence-unknown", every=2)
    arrow = heading_glyph(t.pose.yaw, NOWCAST_ARROWS)
    label = f"{NOWCAST_GLYPH}{robot}"
    ov.point(f"nowcast:{robot}", nc.x, nc.y, arrow, "presence-unknown", label, "presence-unknown")


# -- the widget -------------------------------------------------------------------------------


class MapView(Widget, can_focus=True):
    """Draws the map of a `ConsoleModel` plus a map mirror; posts `CursorMoved`.
    Its look: map.tcss (loaded by the app)."""

    class CursorMoved(Message):
        pass

    class Zoomed(Message):
        """The scale changed by the mouse wheel (the keys' zoom is the screen's)."""

    def __init__(self, model: ConsoleModel, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.model = model
        self.mirror: MapMirror | None = None
        self.vp = Viewport()
        self.cursor = (0.0, 0.0)
        self.heading = 0.0  # radians, for picked poses and new pose markers
        self.follow: str | None = None
        self.selected_marker: str | None = None
        self.selected_skill: str | None = None
        self.fitted = False
        self._rows: dict[int, Strip] = {}
        self._overlay = Overlay(self.vp)
        self._colours: dict[Any, RichColor] = {}
        self._textures: dict[Any, RichColor] = {}  # ground key -> texture colour (16 colours only)
        self._colour_key: Any = None
        self._xs_index: np.ndarray | None = None
        self.rendered_rows = 0  # rows actually rendered (not from the cache): tests, benchmark

    # -- colours ----------------------------------------------------------------------------
    def _palette(self) -> dict[Any, RichColor]:
        key = self.app.theme
        if key == self._colour_key:
            return self._colours
        v = self.app.get_css_variables()

        def col(name: str) -> Color:
            return Color.parse(v.get(name, "#808080"))

        link = col("map-link")
        pal: dict[Any, RichColor] = {}
        self._textures = {}
        for t, name in GROUND_VARS.items():
            base = col(name)
            pal[t] = base.rich_color
            pal[t + 4] = base.blend(link, COVERAGE_TINT).rich_color
            if getattr(self.app, "ansi16", False):
                covered, texture, covered_texture = (Color.parse(c).rich_color for c in GROUND16[t])
                pal[t + 4] = covered
                self._textures[t], self._textures[t + 4] = texture, covered_texture
        pal[OUTSIDE] = col("map-outside").rich_color
        for name, value in v.items():
            if name.startswith(("map-", "status-", "presence-")):
                pal[name] = Color.parse(value).rich_color
        self._colours, self._colour_key = pal, key
        return pal

    def notify_style_update(self) -> None:
        self._colour_key = None
        self._rows.clear()
        super().notify_style_update()

    # -- state in -------------------------------------------------------------------------------
    def set_mirror(self, mirror: MapMirror | None) -> None:
        self.mirror = mirror
        if mirror is not None and mirror.ready and not self.fitted:
            self.fit_known()
        self._index_columns()
        self.redraw_all()

    def tiles_changed(self, tiles: list[tuple[str, int, int]]) -> None:
        """Repaint the rows that show these tiles."""
        m = self.mirror.meta if self.mirror is not None else None
        if m is None:
            return
        rows: set[int] = set()
        for _layer, _tx, ty in tiles:
            y_lo = m.y0 + ty * m.tile * m.cell
            y_hi = y_lo + m.tile * m.cell
            top = self.vp.to_pixel(0, y_hi)[1] // 2
            bottom = self.vp.to_pixel(0, y_lo)[1] // 2
            rows.update(range(max(0, top), min(self.vp.h - 1, bottom) + 1))
        self._dirty(rows)

    def overlays_changed(self) -> None:
        """Recompute the glyphs; repaint only the rows whose glyphs differ."""
        old = self._overlay
        new = self._build_overlay()
        self._overlay = new
        rows = {
            r
            for r in set(old.cells)
            | set(new.cells)
            | {p // 2 for p in set(old.pixels) | set(new.pixels)}
            if old.row_signature(r) != new.row_signature(r)
        }
        self._dirty(rows)

    def redraw_all(self) -> None:
        self._overlay = self._build_overlay()
        self._rows.clear()
        self.refresh()

    def _dirty(self, rows: set[int]) -> None:
        w = self.size.width
        for r in rows:
            self._rows.pop(r, None)
            self.refresh(Region(0, r, w, 1))

    # -- view -------------------------------------------------------------------------------------
    def _index_columns(self) -> None:
        m = self.mirror.meta if self.mirror is not None else None
        if m is None:
            self._xs_index = None
            return
        xs = self.vp.px_x(np.arange(self.vp.w))
        self._xs_index = np.floor((xs - m.x0) / m.cell).astype(np.int64)

    def on_resize(self, event: events.Resize) -> None:
        self.vp.w, self.vp.h = max(1, event.size.width), max(1, event.size.height)
        if not self.fitted and self.mirror is not None and self.mirror.ready:
            self.fit_known()
        self._index_columns()
        self.redraw_all()
        self.post_message(self.CursorMoved())

    def fit(self) -> None:
        """Zoom and centre so the whole site fits."""
        m = self.mirror.meta if self.mirror is not None else None
        if m is None:
            return
        self._fit_box(m.x0, m.x0 + m.width * m.cell, m.y0, m.y0 + m.height * m.cell, pad=1.0)

    def fit_known(self) -> None:
        """Zoom and centre on what is known: robots, markers, the lander and
        the explored area (the whole site is mostly unknown at first)."""
        pts = known_points(self.model, self.mirror)
        if not pts:
            self.fit()
            return
        xs, ys = [p[0] for p in pts], [p[1] for p in pts]
        self._fit_box(min(xs), max(xs), min(ys), max(ys), pad=1.2)

    def _fit_box(self, x0: float, x1: float, y0: float, y1: float, pad: float) -> None:
        if self.size.width == 0:
            return  # not laid out yet: fitted on the first resize
        wm, hm = max(x1 - x0, 20.0) * pad, max(y1 - y0, 20.0) * pad
        self.vp.cx, self.vp.cy = (x0 + x1) / 2, (y0 + y1) / 2
        self.vp.mpp = min(MAX_MPP, max(wm / max(1, self.vp.w), hm / max(1, 2 * self.vp.h), MIN_MPP))
        self.fitted = (
            self.mirror is not None and self.mirror.ready
        )  # without a map: fit again when it comes
        self._index_columns()
        self.redraw_all()

    def set_view(
        self, cx: float | None = None, cy: float | None = None, mpp: float | None = None
    ) -> None:
        if cx is not None:
            self.vp.cx = cx
        if cy is not None:
            self.vp.cy = cy
        if mpp is not None:
            self.vp.mpp = min(MAX_MPP, max(MIN_MPP, mpp))
        self.fitted = True
        self._index_columns()
        self.redraw_all()

    def zoom(self, factor: float) -> None:
        self.set_view(mpp=self.vp.mpp * factor)
        self.keep_cursor_visible(centre=False)

    def zoom_at(self, factor: float, col: int, row: int) -> None:
        """Zoom keeping the ground under cell (col, row) there (the mouse's)."""
        x, y = self.vp.cell_centre(col, row)
        mpp = min(MAX_MPP, max(MIN_MPP, self.vp.mpp * factor))
        k = mpp / self.vp.mpp
        self.set_view(cx=x - (x - self.vp.cx) * k, cy=y - (y - self.vp.cy) * k, mpp=mpp)

    def on_mouse_scroll_up(self, event: events.MouseScrollUp) -> None:
        event.stop()
        self.zoom_at(WHEEL_ZOOM, event.x, event.y)
        self.post_message(self.Zoomed())

    def on_mouse_scroll_down(self, event: events.MouseScrollDown) -> None:
        event.stop()
        self.zoom_at(1 / WHEEL_ZOOM, event.x, event.y)
        self.post_message(self.Zoomed())

    def pan(self, dx_cells: int, dy_cells: int) -> None:
        self.set_view(
            cx=self.vp.cx + dx_cells * self.vp.mpp, cy=self.vp.cy - 2 * dy_cells * self.vp.mpp
        )

    def centre_on(self, x: float, y: float) -> None:
        """Centre the view (snapped to whole pixels, so a still view does not shimmer)."""
        px, py = self.vp.to_pixel(x, y)
        if (px, py) != (self.vp.w // 2, self.vp.h):
            self.set_view(cx=x, cy=y)

    def move_cursor(self, dcol: int, drow: int) -> None:
        x, y = self.cursor
        self.set_cursor(x + dcol * self.vp.mpp, y - 2 * drow * self.vp.mpp)

    def set_cursor(self, x: float, y: float) -> None:
        """Put the cursor at (x, y), kept on the site (its map's grid)."""
        meta = self.mirror.meta if self.mirror is not None else None
        self.cursor = clamp_to_site(meta, x, y)
        self.keep_cursor_visible()
        self.overlays_changed()
        self.post_message(self.CursorMoved())

    def cursor_cell(self) -> tuple[int, int]:
        """(column, row) of the cursor in this widget."""
        return self.vp.to_cell(*self.cursor)

    def uncover_cursor(self, left: int, top: int, right: int, bottom: int) -> None:
        """Pan so the cursor is not under the box [left, right) x [top, bottom) (this
        widget's cells: a notification over the map): to the middle of what is left of it."""
        col, row = self.cursor_cell()
        if left <= col < right and top <= row < bottom:
            target = left // 2 if left >= 4 else (right + self.vp.w) // 2
            self.pan(col - target, 0)
            self.overlays_changed()

    def uncover(self, widgets: Iterable[Widget]) -> None:
        """Keep the cursor clear of these widgets (notifications over the map)."""
        x, y = self.region.x, self.region.y
        for w in widgets:
            r = w.region
            if r.area and w.display:
                self.uncover_cursor(r.x - x, r.y - y, r.right - x, r.bottom - y)

    def keep_cursor_visible(self, centre: bool = False) -> None:
        col, row = self.vp.to_cell(*self.cursor)
        if centre or not (0 <= col < self.vp.w and 0 <= row < self.vp.h):
            if self.follow is not None:
                self.follow = None  # the operator took the view
            self.set_view(cx=self.cursor[0], cy=self.cursor[1])

    def robot_moved(self, robot: str) -> None:
        if self.follow == robot:
            t = self.model.telemetry.get(robot)
            if t is not None:
                self.centre_on(t.pose.x, t.pose.y)
        self.overlays_changed()

    def on_click(self, event: events.Click) -> None:
        self.set_cursor(*self.vp.cell_centre(event.x, event.y))

    # -- overlays ----------------------------------------------------------------------------------
    def _build_overlay(self) -> Overlay:
        """Everything drawn over the ground; the order sets what covers what
        (shapes under glyphs) and whose labels go first (the last drawn)."""
        ov = Overlay(self.vp)
        use = marker_use(self.model)
        objects = self.mirror.objects if self.mirror is not None else None
        mission = self.model.mission
        if objects is not None:
            for r in objects.rss:
                ov.circle(r.x, r.y, r.radius, "map-rss")
        if mission is not None:
            draw_areas(ov, mission, use)
        draw_goals(ov, self.model, self.selected_skill)
        if objects is not None:
            draw_objects(ov, objects)
        if mission is not None:
            draw_markers(ov, mission, use, self.selected_marker)
        draw_robots(ov, self.model, self.follow)
        ov.place_labels()
        ov.cursor(self.cursor[0], self.cursor[1], heading_glyph(self.heading, POSE_ARROWS))
        return ov

    # -- rendering ---------------------------------------------------------------------------------
    def _pixel_row(self, py: int) -> list[Any]:
        """Colour keys of pixel row `py`: the ground's, the shapes' over it."""
        keys = ground_classes(self.mirror, self.vp, py, self._xs_index).tolist()
        for px, var in self._overlay.pixels.get(py, {}).items():
            if px < len(keys):
                keys[px] = var
        return keys

    def _glyphs(self, y: int, pal: dict[Any, RichColor]) -> dict[int, Glyph]:
        """The overlay's glyphs of row `y`, in colours (the cursor's reversed)."""
        return {
            col: (
                ch,
                pal.get(var) or pal["map-label"],
                bold,
                pal["map-cursor"] if var == CURSOR_FG else None,
            )
            for col, (ch, var, bold) in self._overlay.cells.get(y, {}).items()
        }

    def render_line(self, y: int) -> Strip:
        strip = self._rows.get(y)
        if strip is not None:
            return strip
        self.rendered_rows += 1
        pal = self._palette()
        vp = self.vp
        top, bottom = self._pixel_row(2 * y), self._pixel_row(2 * y + 1)
        origin = round(vp.cx / vp.mpp) - vp.w // 2  # texture fixed to the ground, not the screen
        strip = Strip(
            halfblock_row(
                top,
                bottom,
                pal,
                self._glyphs(y, pal),
                lambda i, k: _texture(origin + i, y, k),
                self._textures,
            )
        ).crop_extend(0, self.size.width, None)
        self._rows[y] = strip
        return strip


def _unknown_texture(x: int, row: int) -> str:
    return "·" if (x + 2 * row) % 4 == 0 else " "


def _sand_texture(x: int, row: int) -> str:
    return "~" if (x + row) % 3 == 0 else " "


# ground class -> its pattern at (x, row); free ground has none
TEXTURES: dict[int, Callable[[int, int], str]] = {
    T_UNKNOWN: _unknown_texture,
    T_ROCK: lambda x, row: "▴",
    T_SLOW: _sand_texture,
}


def _texture(x: int, row: int, key: Any) -> str:
    """Patterns where a whole cell is one ground class (colour is not alone)."""
    if not isinstance(key, int) or key == OUTSIDE:
        return " "
    pattern = TEXTURES.get(key % 4)
    return pattern(x, row) if pattern is not None else " "
