"""The schedule panel: a column per robot, synchronized section on top, the
unsynchronized plan below a divider that runs across all columns.

One Line-API widget (`ScrollView.render_line`) draws it: only the visible
lines are rendered, there is no widget per row, and a change to one robot's
list re-lays out only that robot's column and repaints only the visible lines
that show something else (telemetry: the header and progress lines). Column
headers stay on top while the rows scroll; columns scroll horizontally when
they do not fit. Which line of which column goes where: paint.py (the view's
`Painter`); how each line of a column is drawn: lines.py.
"""

from __future__ import annotations

from textual import events
from textual.binding import Binding
from textual.geometry import Region, Size
from textual.message import Message
from textual.scroll_view import ScrollView
from textual.strip import Strip

from console.state.model import ConsoleModel
from console.state.text import STATUS_CSS
from console.widgets.schedule.lines import (
    HEADER_H,
    MIN_W,
    Column,
    Styles,
    build_column,
    click_hit,
    hidden_robots,
)
from console.widgets.schedule.paint import Painter

STATIC_W = 16
MAX_W = 46


class ScheduleView(ScrollView, can_focus=True):
    """Draws the schedule from a `ConsoleModel` (look: schedule.tcss); posts `CursorMoved`."""

    COMPONENT_CLASSES = {
        *(f"schedule--{c}" for c in STATUS_CSS.values()),
        "schedule--cursor",
        "schedule--cursor-blur",
        "schedule--robot",
        "schedule--online",
        "schedule--offline",
        "schedule--unknown",
        "schedule--dim",
        "schedule--divider",
        "schedule--tag",
        "schedule--mark",
        "schedule--progress",
        "schedule--battery-low",
        "schedule--rule",
        "schedule--more",
        "schedule--stale",
        "schedule--stale-head",
        "schedule--check-error",  # plan checks' glyphs (console/state/plan.py)
        "schedule--check-warning",
        "schedule--check-waived",
    }

    BINDINGS = [
        Binding("up", "cursor(0, -1)", "Up", show=False),
        Binding("down", "cursor(0, 1)", "Down", show=False),
        Binding("left", "cursor(-1, 0)", "Left", show=False),
        Binding("right", "cursor(1, 0)", "Right", show=False),
        Binding("home", "cursor_end(-1)", "First", show=False),
        Binding("end", "cursor_end(1)", "Last", show=False),
        Binding("pageup", "cursor_page(-1)", "Page up", show=False),
        Binding("pagedown", "cursor_page(1)", "Page down", show=False),
    ]

    class CursorMoved(Message):
        def __init__(self, robot: str | None, skill_id: str | None) -> None:
            super().__init__()
            self.robot = robot
            self.skill_id = skill_id

    def __init__(self, model: ConsoleModel, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.model = model
        self.columns: list[Column] = []
        self._col_index: dict[str, int] = {}
        self.sync_h = 1
        self.total_lines = 3
        self.cursor_col = 0
        self.drafts: frozenset[str] = frozenset()  # skills with unapplied edits (marked '*')
        self.expand_static = False
        self.painter = Painter(self)
        self._last_width = -1
        self.last_key: events.Key | None = None  # a robot command acts on a press made here

    def on_key(self, event: events.Key) -> None:
        self.last_key = event

    # -- the selection lives in the model (other screens act on it) ----------------
    @property
    def cursor_id(self) -> str | None:
        """The skill under the cursor."""
        return self.model.selection.skill

    @cursor_id.setter
    def cursor_id(self, skill_id: str | None) -> None:
        self.model.selection.skill = skill_id

    @property
    def marks(self) -> list[str]:
        """Skills marked for a new barrier (one per robot)."""
        return self.model.selection.marks

    @marks.setter
    def marks(self, marks: list[str]) -> None:
        self.model.selection.marks = marks

    # -- model -> layout -----------------------------------------------------------
    @property
    def cursor_robot(self) -> str | None:
        if 0 <= self.cursor_col < len(self.columns):
            return self.columns[self.cursor_col].robot
        return None

    def rebuild(self, robots: set[str] | None = None) -> None:
        """Re-lay out the columns of `robots` (all when None) and repaint."""
        order = self.model.robot_order()
        if robots is None or [c.robot for c in self.columns] != order:
            self._build(order)
            self._relayout()
        else:
            before = (self.sync_h, self.total_lines)
            changed = self._rebuild_columns(robots)
            self._relayout([new for _, new in changed])
            if self.cursor_id in self.columns[self.cursor_col].line_of:
                self._refresh_rebuilt(changed, *before)
                return
        self._keep_cursor()
        self.refresh()

    def _build(self, order: list[str]) -> None:
        """Every robot's column, in this order."""
        self.columns = [
            build_column(self.model, r, self.model.robot_kind(r) == "static") for r in order
        ]
        self._col_index = {c.robot: i for i, c in enumerate(self.columns)}
        if len(self.painter.summaries) > 50_000:
            self.painter.summaries.clear()

    def _rebuild_columns(self, robots: set[str]) -> list[tuple[Column, Column]]:
        """These robots' columns built again: (before, now) of each."""
        changed: list[tuple[Column, Column]] = []
        for r in robots:
            i = self._col_index.get(r)
            if i is not None:
                old = self.columns[i]
                self.columns[i] = build_column(self.model, r, old.static)
                changed.append((old, self.columns[i]))
        return changed

    def _refresh_rebuilt(
        self, changed: list[tuple[Column, Column]], old_sync_h: int, old_total: int
    ) -> None:
        """Repaint only the visible lines that show something else now: in the
        changed columns, and across all columns from the divider down when the
        synchronized section grew or shrank."""
        for old, new in changed:
            self._refresh_changed_lines(old, new, old_sync_h)
        if self.sync_h != old_sync_h:
            start = min(self.sync_h, old_sync_h)
            self._refresh_content_lines(
                0, self.size.width, range(start, max(self.total_lines, old_total))
            )

    def refresh_uplinking(self, robot: str) -> None:
        """A second passed: the header's and the rows' command ages."""
        col = self.column_of(robot)
        if col is not None:
            lines = [n for n, key in enumerate(col.sync_keys) if key[3]]
            lines += [self.sync_h + 1 + k for k, key in enumerate(col.idle_keys) if key[2]]
            self._refresh_header_and(col, lines)

    def refresh_telemetry(self, robot: str) -> None:
        """New telemetry: only the header and the progress lines show it."""
        col = self.column_of(robot)
        if col is not None:
            lines = [line for line, (_, kind) in enumerate(col.sync) if kind == "progress"]
            self._refresh_header_and(col, lines)

    def column_of(self, robot: str) -> Column | None:
        i = self._col_index.get(robot)
        return self.columns[i] if i is not None else None

    def _refresh_header_and(self, col: Column, lines: list[int]) -> None:
        """Repaint a column's header and these content lines of it."""
        x, w = col.x - int(self.scroll_x), col.width + 1
        self.refresh(Region(x, 0, w, HEADER_H - 1))
        self._refresh_content_lines(x, w, lines)

    def _visible_lines(self) -> range:
        sy = int(self.scroll_y)
        return range(sy, sy + max(0, self.size.height - HEADER_H))

    def _refresh_content_lines(self, x: int, width: int, lines: range | list[int]) -> None:
        """Repaint these content lines (those visible) between x and x+width."""
        visible = self._visible_lines()
        ys = [HEADER_H + line - visible.start for line in lines if line in visible]
        for y in ys:
            self.refresh(Region(x, y, width, 1))

    def _refresh_changed_lines(self, old: Column, new: Column, old_sync_h: int) -> None:
        x, w = new.x - int(self.scroll_x), new.width + 1
        self.refresh(Region(x, 0, w, HEADER_H - 1))  # presence, battery, activity
        changed = [
            line
            for line in self._visible_lines()
            if old.line_key(line, old_sync_h) != new.line_key(line, self.sync_h)
        ]
        # progress lines also show telemetry and barrier partners' states
        changed += [line for line, (_, kind) in enumerate(new.sync) if kind == "progress"]
        self._refresh_content_lines(x, w, changed)

    def _relayout(self, only: list[Column] | None = None) -> None:
        sync_h = max([1, *(len(c.sync) for c in self.columns)])
        idle_h = max([1, *(len(c.idle) for c in self.columns)])
        if sync_h != self.sync_h:
            only = None  # every column's plan rows move
        self.sync_h = sync_h
        self.total_lines = self.sync_h + 1 + idle_h
        self._place_columns()
        for c in self.columns if only is None else only:
            c.place_lines(self.sync_h)

    def _place_columns(self) -> None:
        avail = max(self.scrollable_content_region.width, 20) if self.is_mounted else 80
        self._last_width = avail
        static_w, w = self._widths(avail)
        x = 0
        for c in self.columns:
            c.x = x
            c.width = static_w if c.static else w
            x += c.width + 1
        self._set_virtual_size(Size(max(x - 1, 1), HEADER_H + self.total_lines))

    def _widths(self, avail: int) -> tuple[int, int]:
        """A static column's width, and a dynamic one's: they share what the statics leave."""
        statics = sum(1 for c in self.columns if c.static)
        dyn = len(self.columns) - statics
        static_w = STATIC_W if not self.expand_static else MIN_W + 6
        if not dyn:
            return static_w, MAX_W
        w = (avail + 1 - statics * (static_w + 1)) // dyn - 1
        return static_w, max(MIN_W, min(MAX_W, w))

    def _set_virtual_size(self, size: Size) -> None:
        old = self.virtual_size
        if size == old:
            return
        if (
            self.is_mounted
            and size.width == old.width
            and min(size.height, old.height) > self.size.height
        ):
            # only the scroll range grows or shrinks and the scrollbars stay as
            # they are: update them without the screen's layout pass, which
            # reflows every widget (the editor's too) for tens of ms
            self.set_reactive(ScheduleView.virtual_size, size)
            self._scroll_update(size)
        else:
            self.virtual_size = size

    def on_resize(self, event: events.Resize) -> None:
        if self.scrollable_content_region.width != self._last_width:
            self._relayout()
            self._scroll_cursor_visible()
            self.refresh()

    # -- cursor -----------------------------------------------------------------
    def _keep_cursor(self) -> None:
        if not self.columns:
            self.cursor_col, self.cursor_id = 0, None
            return
        self.cursor_col = min(max(self.cursor_col, 0), len(self.columns) - 1)
        col = self.columns[self.cursor_col]
        if self.cursor_id is not None and self.cursor_id in col.line_of:
            return
        # the skill moved to another robot's column? (not possible today) or was deleted
        moved = self._column_with(self.cursor_id)
        if moved is not None:
            self.cursor_col = moved
            return
        # prefer the first unsynchronized skill, else the active one, else the last
        self.cursor_id = col.resting_id()
        self._post_cursor()

    def _column_with(self, skill_id: str | None) -> int | None:
        """The index of the column of the robot that has this skill (None: none has)."""
        owner = self.model.owner(skill_id) if skill_id is not None else None
        return self._col_index.get(owner) if owner is not None else None

    def _post_cursor(self) -> None:
        self.post_message(self.CursorMoved(self.cursor_robot, self.cursor_id))

    def select(self, skill_id: str | None = None, robot: str | None = None) -> None:
        """Put the cursor on a skill (or a robot's column)."""
        if skill_id is not None:
            i = self._column_with(skill_id)
            if i is None:
                return
            self.cursor_col, self.cursor_id = i, skill_id
        elif robot is not None and robot in self._col_index:
            self.cursor_col = self._col_index[robot]
            col = self.columns[self.cursor_col]
            self.cursor_id = col.resting_id()
        self._scroll_cursor_visible()
        self.refresh()
        self._post_cursor()

    def _cursor_line(self) -> int:
        if not self.columns:
            return 0
        col = self.columns[self.cursor_col]
        if self.cursor_id is None:
            return 0
        return col.line_of.get(self.cursor_id, 0)

    def _scroll_cursor_visible(self) -> None:
        if not self.columns:
            return
        region = self.scrollable_content_region
        col = self.columns[self.cursor_col]
        x = _scrolled_to(self.scroll_x, col.x, col.width, region.width)
        line = self._cursor_line()
        rows = max(1, region.height - HEADER_H)
        y = _scrolled_to(self.scroll_y, line, 1, rows)
        if line <= self.sync_h and self.sync_h < rows and y > 0 and line - y < 2:
            y = max(0, line - 1)
        self.scroll_to(x=x, y=y, animate=False, immediate=True)

    def action_cursor(self, dx: int, dy: int) -> None:
        if not self.columns:
            return
        if dx:
            line = self._cursor_line()
            self.cursor_col = min(max(self.cursor_col + dx, 0), len(self.columns) - 1)
            self.cursor_id = _nearest(self.columns[self.cursor_col], line)
        elif dy:
            col = self.columns[self.cursor_col]
            if not col.ids:
                return
            self.cursor_id = _stepped(col, self.cursor_id, dy)
        self._scroll_cursor_visible()
        self.refresh()
        self._post_cursor()

    def action_cursor_end(self, direction: int) -> None:
        if not self.columns:
            return
        col = self.columns[self.cursor_col]
        if col.ids:
            self.cursor_id = col.ids[0] if direction < 0 else col.ids[-1]
        self._scroll_cursor_visible()
        self.refresh()
        self._post_cursor()

    def action_cursor_page(self, direction: int) -> None:
        rows = max(1, self.scrollable_content_region.height - HEADER_H - 1)
        if not self.columns:
            return
        col = self.columns[self.cursor_col]
        if not col.ids:
            return
        self.cursor_id = _stepped(col, self.cursor_id, direction * rows)
        self._scroll_cursor_visible()
        self.refresh()
        self._post_cursor()

    def toggle_mark(self, skill_id: str) -> bool:
        if skill_id in self.marks:
            self.marks.remove(skill_id)
            marked = False
        else:
            # one skill per robot: a new mark replaces that robot's previous one
            owner = self.model.owner(skill_id)
            self.marks = [m for m in self.marks if self.model.owner(m) != owner]
            self.marks.append(skill_id)
            marked = True
        self.refresh()
        return marked

    def set_drafts(self, drafts: frozenset[str]) -> None:
        if drafts != self.drafts:
            self.drafts = drafts
            self.refresh()

    def clear_marks(self) -> None:
        self.marks = []
        self.refresh()

    def set_expand_static(self, expand: bool) -> None:
        self.expand_static = expand
        self._relayout()
        self._scroll_cursor_visible()
        self.refresh()

    def on_click(self, event: events.Click) -> None:
        hit = click_hit(self.columns, int(self.scroll_x) + event.x, event.y, int(self.scroll_y))
        if hit is not None:
            self.cursor_col, skill = hit
            self.cursor_id = skill or self.cursor_id
            self.refresh()
            self._post_cursor()

    # -- rendering ----------------------------------------------------------------
    def styles_now(self) -> Styles:
        key = (self.app.theme, self.has_focus)
        cached = getattr(self, "_style_cache", None)
        if cached is not None and cached[0] == key:
            return cached[1]
        get = self.get_component_rich_style
        out = {name.removeprefix("schedule--"): get(name) for name in self.COMPONENT_CLASSES}
        out["base"] = self.rich_style
        self._style_cache = (key, out)
        return out

    def notify_style_update(self) -> None:
        self._style_cache = None
        super().notify_style_update()

    def render_line(self, y: int) -> Strip:
        return self.painter.line(y)

    def hidden_robots(self) -> tuple[int, int]:
        """(columns cut or hidden on the left, on the right) of the view now."""
        x0 = int(self.scroll_x)
        return hidden_robots(self.columns, x0, x0 + self.scrollable_content_region.width)


def _scrolled_to(offset: float, start: int, length: int, span: int) -> float:
    """The scroll offset nearest `offset` that shows [start, start + length) in `span` cells."""
    if start < offset:
        return start
    if start + length > offset + span:
        return start + length - span
    return offset


def _nearest(col: Column, line: int) -> str | None:
    """The skill of `col` whose row is nearest `line` (the upper one of two), None: it has none."""
    if not col.line_of:
        return None
    return min(col.line_of, key=lambda sid: (abs(col.line_of[sid] - line), col.line_of[sid]))


def _stepped(col: Column, skill_id: str | None, n: int) -> str:
    """The skill n rows from `skill_id` in `col` (from the first when not in it), clamped."""
    i = col.ids.index(skill_id) if skill_id in col.ids else 0
    return col.ids[min(max(i + n, 0), len(col.ids) - 1)]
