"""The timeline (F7): the plan's predicted future, one lane per robot.

Layout: title bar / the lanes (console/widgets/timeline.py) / the plan's
end ("plan ends 15:42 · critical: lru2") / the selected skill in a line /
footer. The selection is the schedule's (the model's): arrows move it
between skills and robots, enter shows it in the schedule. +/- zoom around
it, 0 fits the whole mission (what happened, then the plan), shift+arrows
scroll. Redrawn when the app says
the plan changed (a new forecast), at once when shown, else when shown next.
"""

from __future__ import annotations

from pathlib import Path

from rich.text import Text
from textual import on
from textual.app import ComposeResult
from textual.binding import Binding
from textual.screen import Screen
from textual.signal import Signal
from textual.widgets import Footer, Static

from console.bindings import bind, bindings
from console.state import timeline as tl
from console.state.changes import StateChange, Topic
from console.state.model import ConsoleModel
from console.widgets.bars import TitleBar
from console.widgets.timeline.view import TimelineView

TCSS = [
    Path(__file__).with_name("timeline.tcss"),
    Path(__file__).parents[1] / "widgets" / "timeline" / "timeline.tcss",
]
# the forecast, and what it is made from
TOPICS = frozenset({Topic.FORECAST, Topic.MISSION, Topic.FLEET, Topic.TELEMETRY})


class TimelineScreen(Screen):
    SCOPE = "timeline"  # its own palette entries (console/commands.py)
    BINDINGS = [
        *bindings("timeline"),
        bind("app.help", "app.help", show=True),
        Binding("escape", "app.show_mission", "Schedule", show=False),
    ]
    CSS_PATH = TCSS

    def __init__(self, model: ConsoleModel, changes: Signal[StateChange]) -> None:
        super().__init__()
        self.model = model
        self.changes = changes
        self.view = TimelineView(model, id="timeline")
        self.title_bar = TitleBar(id="title")
        self._summary = Static("", id="timeline-summary")
        self._details = Static("", id="timeline-details")
        self.win: tl.Window | None = None
        self.top = 0
        self._stale = False

    def compose(self) -> ComposeResult:
        yield self.title_bar
        yield self.view
        yield self._summary
        yield self._details
        yield Footer()

    def on_mount(self) -> None:
        self.changes.subscribe(self, self._changed)
        self.app.theme_changed_signal.subscribe(self, lambda _t: self.redraw())

    def on_resize(self) -> None:
        if self.win is not None:  # the first draw comes with the screen's resume
            self.call_after_refresh(self.redraw)

    def _changed(self, change: StateChange) -> None:
        if not change.topics & TOPICS:
            return
        if self.app.screen is self:
            self.redraw()
        else:
            self._stale = True

    def on_screen_resume(self) -> None:
        self._stale = False
        self.call_after_refresh(self.redraw)  # once laid out: the lanes' width is known

    # -- drawing ----------------------------------------------------------------------------
    @property
    def order(self) -> list[str]:
        return self.model.robot_order()

    def _whole(self) -> tuple[float, float]:
        """From now to the plan's end (or its last predicted skill's), in mission time."""
        fc, clock = self.model.plan.forecast, self.model.clock
        if fc is None:
            return 0.0, 3600.0
        ends = [r.end for r in fc.robots.values() if r.end is not None]
        end = fc.end if fc.end is not None else max(ends, default=fc.now + 600 / clock.speed)
        now = clock.of_ts(fc.now)
        return now, max(clock.of_ts(end), now + 60)

    def redraw(self) -> None:
        if not self.is_mounted or self.view.size.width == 0:
            return
        width = self.view.lanes_w
        if self.win is None:
            self.win = tl.fit(*self._whole(), width)
        elif self.win.width != width:
            self.win = tl.Window(self.win.t0, self.win.dt, width)
        self._keep_selection_visible()
        self.view.show(self.win, self.order, self.top)
        m = self.model.mission
        name = m.name if m is not None else "no mission"
        self.title_bar.update(
            Text.assemble(("missionctl", "bold"), "  ", ("timeline", "bold"), f"  {name}")
        )
        self._summary.update(self._summary_text(self.win))
        fc, clock = self.model.plan.forecast, self.model.clock
        self._details.update(tl.details(m, fc, self.model.selection.skill, clock) if m else "")

    def _summary_text(self, win: tl.Window) -> str:
        """The forecast's summary, the link delay, the zoom, what ▔ is."""
        fc, clock = self.model.plan.forecast, self.model.clock
        summary = fc.summary(clock.ts_text) if fc is not None else "no forecast yet"
        delay = self.model.plan.link_delay_s
        link = f" · link delay {clock.duration_text(delay)}" if delay else ""
        zoom = f" · {tl.fmt_step(win.dt)} per column"
        at_sync = " · ▔ as planned at sync" if self.model.plan.planned else ""
        return summary + link + zoom + at_sync

    def _keep_selection_visible(self) -> None:
        sid = self.model.selection.skill
        robot = self.model.owner(sid) if sid else None
        order = self.order
        if robot in order:
            i = order.index(robot)
            shown = self.view.lanes_shown
            if i < self.top:
                self.top = i
            elif i >= self.top + shown:
                self.top = i - shown + 1
        self.top = max(0, min(self.top, max(0, len(order) - 1)))

    # -- selection ----------------------------------------------------------------------------
    def _select(self, sid: str | None, scroll: bool = True) -> None:
        if sid is None or self.model.mission is None:
            return
        self.model.selection.skill = sid
        span = tl.times(self.model.mission, self.model.plan.forecast, sid, self.model.clock)
        if scroll and span is not None and self.win is not None:
            self.win = self.win.showing(*span)
        self.redraw()

    def _selected_robot(self) -> str | None:
        sid = self.model.selection.skill
        robot = self.model.owner(sid) if sid else None
        return robot or (self.order[0] if self.order else None)

    def _step(self, by: int) -> None:
        robot = self._selected_robot()
        if robot is None:
            return
        ids = [s.id for s in self.model.task(robot)]
        sid = self.model.selection.skill
        if not ids:
            return
        i = ids.index(sid) + by if sid in ids else 0
        self._select(ids[max(0, min(len(ids) - 1, i))])

    def _lane(self, by: int) -> None:
        order = self.order
        robot = self._selected_robot()
        if robot is None or self.model.mission is None:
            return
        i = order.index(robot) + by if robot in order else 0
        if not 0 <= i < len(order):
            return
        sid = self.model.selection.skill
        clock = self.model.clock
        span = tl.times(self.model.mission, self.model.plan.forecast, sid, clock) if sid else None
        target = self.model.task(order[i])
        if not target:
            self.top = max(0, min(self.top + by, len(order) - 1))
            self.redraw()
            return
        at = (span[0] + span[1]) / 2 if span else self._whole()[0]
        self._select(tl.nearest(self.model.mission, self.model.plan.forecast, target, at, clock))

    def action_timeline_prev(self) -> None:
        self._step(-1)

    def action_timeline_next(self) -> None:
        self._step(1)

    def action_timeline_up(self) -> None:
        self._lane(-1)

    def action_timeline_down(self) -> None:
        self._lane(1)

    @on(TimelineView.Selected)
    def _clicked(self, event: TimelineView.Selected) -> None:
        self._select(event.skill_id, scroll=False)

    def action_timeline_schedule(self) -> None:
        self.app.switch_mode("mission")

    # -- zoom and scroll ---------------------------------------------------------------------
    def _around(self) -> float:
        sid = self.model.selection.skill
        fc, clock = self.model.plan.forecast, self.model.clock
        span = tl.times(self.model.mission, fc, sid, clock) if sid else None
        if span is not None and self.win is not None and span[0] <= self.win.t1:
            return max(self.win.t0, span[0])
        return self.win.t0 + self.win.dt * self.win.width / 2 if self.win else 0.0

    def _zoom(self, step: int) -> None:
        if self.win is not None:
            self.win = self.win.zoomed(step, self._around())
            self.redraw()

    def action_timeline_zoom_in(self) -> None:
        self._zoom(-1)

    def action_timeline_zoom_out(self) -> None:
        self._zoom(1)

    def action_timeline_fit(self) -> None:
        """What happened (actual bars over the plan as synced) and the plan ahead."""
        now, end = self._whole()
        start = tl.first_start(self.model.mission, self.model.clock, now)
        self.win = tl.fit(start, end, self.view.lanes_w)
        self.redraw()

    def action_timeline_now(self) -> None:
        if self.win is not None:
            now = self._whole()[0]
            self.win = tl.Window(
                now - self.win.dt * self.win.width / 4, self.win.dt, self.win.width
            )
            self.redraw()

    def _pan(self, quarters: int) -> None:
        if self.win is not None:
            w = self.win
            self.win = tl.Window(w.t0 + quarters * w.dt * w.width / 4, w.dt, w.width)
            self.redraw()

    def action_timeline_earlier(self) -> None:
        self._pan(-1)

    def action_timeline_later(self) -> None:
        self._pan(1)
