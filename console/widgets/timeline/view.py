"""The timeline: one lane per robot on a time axis (Line API: only what shows is drawn).

What each cell shows is decided in console/state/timeline.py; here the cells
become styled segments (component classes `timeline--<style>`, timeline.tcss)
and a click selects the bar under the mouse. The screen owns the window
(zoom, scroll) and the selection, and calls `show` when either or the plan
changed.
"""

from __future__ import annotations

from rich.segment import Segment
from rich.style import Style
from textual import events
from textual.message import Message
from textual.strip import Strip
from textual.widget import Widget

from console.state import timeline as tl
from console.state.model import ConsoleModel
from console.state.text import STATUS_CSS

AXIS_H = 2  # tick labels, tick marks
NAME_MAX = 10  # cells of a robot's name, at most

STYLES = (
    *STATUS_CSS.values(),
    "wait",
    "hatch",
    "delay",
    "now",
    "cursor",
    "critical",
    "link",
    "axis",
    "axis-label",
    "name",
    "name-selected",
    "planned",
)


class TimelineView(Widget):
    COMPONENT_CLASSES = {f"timeline--{s}" for s in STYLES}

    class Selected(Message):
        """A bar was clicked."""

        def __init__(self, skill_id: str) -> None:
            super().__init__()
            self.skill_id = skill_id

    def __init__(self, model: ConsoleModel, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.model = model
        self.win: tl.Window | None = None
        self.top = 0  # first lane shown
        self.order: list[str] = []
        self.rows: list[list[tl.Cell]] = []  # what each line of the lanes area shows
        self.row_bars: dict[int, list[tl.Bar]] = {}  # lane line -> its bars (clicks)
        self.axis_rows: tuple[list[tl.Cell], list[tl.Cell]] = ([], [])
        self._looks: dict[tuple[str, ...], Style] = {}  # style names -> their Rich style

    # -- geometry ------------------------------------------------------------------------
    @property
    def name_w(self) -> int:
        return min(NAME_MAX, max([4, *(len(r) for r in self.order)])) + 1

    @property
    def lanes_w(self) -> int:
        return max(10, self.size.width - self.name_w)

    @property
    def lanes_shown(self) -> int:
        return max(1, (self.size.height - AXIS_H + 1) // 2)

    # -- what shows ----------------------------------------------------------------------
    def show(self, win: tl.Window, order: list[str], top: int) -> None:
        """Lay out the lanes of `order` from `top` in `win`, then repaint."""
        self.win, self.order, self.top = win, order, top
        plan, clock = self.model.plan, self.model.clock
        fc = plan.forecast
        now = clock.of_ts(fc.now) if fc is not None else win.t0
        reach = now + clock.span(plan.link_delay_s)
        shown = order[top : top + self.lanes_shown]
        sel = self.model.selection.skill
        lanes = self._bars(shown, win, sel)
        critical = frozenset(fc.critical_path()) if fc is not None else frozenset()
        links = tl.links(lanes, shown, win)
        at_sync = self._planned_at_sync()
        self.rows, self.row_bars = [], {}
        for i, robot in enumerate(shown):
            self.row_bars[len(self.rows)] = lanes.get(robot, [])
            self.rows.append(
                tl.lane(lanes.get(robot, []), win, now, reach, selected=sel, critical=critical)
            )
            spacer = tl.spacer(links.get(i, set()), win.width)
            self.rows.append(tl.planned(spacer, at_sync.get(robot, ()), win))
        self.axis_rows = tl.axis(win, now, clock)
        self.refresh()

    def _bars(self, shown: list[str], win: tl.Window, sel: str | None) -> dict[str, list[tl.Bar]]:
        """Each shown robot's bars in the window (none before there is a mission)."""
        mission, fc, clock = self.model.mission, self.model.plan.forecast, self.model.clock
        if not mission:
            return {}
        return {r: tl.bars(mission, fc, r, clock, win.t0, win.t1, win.dt, sel) for r in shown}

    def _planned_at_sync(self) -> dict[str, list[tuple[float, float]]]:
        """Robot -> the spans its skills were planned at when synchronized."""
        at_sync: dict[str, list[tuple[float, float]]] = {}
        for sid, span in self.model.plan.planned.items():
            at_sync.setdefault(self.model.owner(sid) or "", []).append(span)
        return at_sync

    def notify_style_update(self) -> None:
        self._looks = {}  # the theme changed
        super().notify_style_update()

    def _look(self, names: tuple[str, ...]) -> Style:
        """The Rich style of a cell's style names (cached: a frame has few kinds of cell)."""
        look = self._looks.get(names)
        if look is None:
            look = self.rich_style
            for n in names:
                look += self.get_component_rich_style(f"timeline--{n}", partial=True)
            self._looks[names] = look
        return look

    def _segments(self, cells: list[tl.Cell]) -> list[Segment]:
        """Runs of cells with the same styles, one segment each."""
        out: list[Segment] = []
        run: list[str] = []
        names: tuple[str, ...] | None = None
        for ch, own in cells:
            if own != names and run:
                out.append(Segment("".join(run), self._look(names or ())))
                run = []
            names = own
            run.append(ch)
        if run:
            out.append(Segment("".join(run), self._look(names or ())))
        return out

    def render_line(self, y: int) -> Strip:
        st = {"base": self._look(()), "name": self._look(("name",))}
        st["name-selected"] = self._look(("name-selected",))
        w = self.size.width
        shown = self._line(y)
        if shown is None:
            return Strip([Segment(" " * w, st["base"])], w)
        cells, name = shown
        owner = self.model.owner(self.model.selection.skill or "")
        nst = st["name-selected"] if name and name == owner else st["name"]
        segs = [Segment(tl_name(name, self.name_w), nst), *self._segments(cells[: self.lanes_w])]
        return Strip(segs).adjust_cell_length(w, st["base"])

    def _line(self, y: int) -> tuple[list[tl.Cell], str] | None:
        """Screen row y's cells and the robot named beside them ('' on the
        axis and under a lane); None below the last lane."""
        if y < AXIS_H:
            return self.axis_rows[y], ""
        k = y - AXIS_H
        if k >= len(self.rows):
            return None
        return self.rows[k], self.order[self.top + k // 2] if k % 2 == 0 else ""

    def on_click(self, event: events.Click) -> None:
        k = event.y - AXIS_H
        x = event.x - self.name_w
        if self.win is None or k < 0 or k % 2 or x < 0:
            return
        bar = self._bar_at(k, self.win.t0 + (x + 0.5) * self.win.dt, self.win.dt)
        if bar is not None:
            self.post_message(self.Selected(bar.id))

    def _bar_at(self, k: int, t: float, dt: float) -> tl.Bar | None:
        """The bar of lane line k at time t, a cell's width of slack on either side."""
        return next(
            (b for b in self.row_bars.get(k, []) if b.start - dt <= t <= b.end + dt / 2), None
        )


def tl_name(name: str, width: int) -> str:
    text = name[: width - 1]
    return text + " " * (width - len(text))
