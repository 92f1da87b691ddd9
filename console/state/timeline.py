"""What the timeline screen draws, cell by cell — no Textual here.

One lane per robot: a bar per skill over its time (finished skills at their
actual times, the others where the forecast puts them), in its status's
colour and starting with its status glyph; a barrier wait as a dotted line
before the bar; spans out of comms coverage hatched (╱); the link-delay band
(·) from now to when a command sent now reaches the robots; a `now` column
(│). Between two lanes, a spacer line carries the barrier links (┆) joining
partners at the barrier's start. A cell is a character and the names of the
styles it takes (the widget turns them into Rich styles).

Times here are mission times (console/state/clock.py: sim seconds while a sim
runs, else POSIX seconds): the forecast's and the log's wall stamps are turned
into mission time as they are read, so the axis, the bars' spans, waits and
coverage read in the sim's time at any speed.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from backend.core.model import FINISHED, Mission, SkillInstance, Status
from backend.core.plan.forecast import Forecast, SkillForecast, Span
from console.state.clock import MissionClock
from console.state.text import GLYPHS, STATUS_CSS, skill_title

ZOOMS = (1, 2, 5, 10, 15, 30, 60, 120, 300, 600, 900, 1800, 3600)  # seconds per cell
TICKS = (5, 10, 15, 30, 60, 120, 300, 600, 900, 1800, 3600, 7200, 10800, 21600, 43200, 86400)
LABEL_CELLS = 9  # room a tick's label needs ("15:42:10 ")

Cell = tuple[str, tuple[str, ...]]  # a character, the names of its styles


@dataclass(frozen=True, slots=True)
class Bar:
    id: str
    start: float
    end: float
    status: Status
    label: str
    ready: float  # a barrier wait runs from here to start
    barrier: str | None
    out: tuple[Span, ...]  # spans out of comms coverage


@dataclass
class Window:
    t0: float  # the time at the left edge
    dt: float  # seconds per cell
    width: int  # cells

    @property
    def t1(self) -> float:
        return self.t0 + self.dt * self.width

    def col(self, t: float) -> int:
        return math.floor((t - self.t0) / self.dt)

    def zoomed(self, step: int, around: float) -> Window:
        """One zoom level in (step -1) or out (+1), keeping `around` in place."""
        k = min(range(len(ZOOMS)), key=lambda i: abs(ZOOMS[i] - self.dt))
        dt = float(ZOOMS[max(0, min(len(ZOOMS) - 1, k + step))])
        x = (around - self.t0) / self.dt
        return Window(around - x * dt, dt, self.width)

    def showing(self, start: float, end: float) -> Window:
        """Scrolled (not zoomed) so that [start, end] shows, if it does not."""
        if start >= self.t0 and end <= self.t1:
            return self
        return Window(start - self.dt * self.width / 4, self.dt, self.width)


def fit(start: float, end: float, width: int) -> Window:
    """The closest zoom showing [start, end] in `width` cells, with a margin."""
    span = max(end - start, 1.0) * 1.1
    dt = next((z for z in ZOOMS if z * width >= span), ZOOMS[-1])
    return Window(start - 0.05 * span, float(dt), width)


# -- bars ---------------------------------------------------------------------------------


def _label(s: SkillInstance) -> str:
    return f"{GLYPHS[s.status]} {skill_title(s)}"


def _spans(spans: Iterable[Span], clock: MissionClock) -> tuple[Span, ...]:
    return tuple((clock.of_ts(a), clock.of_ts(b)) for a, b in spans)


def bars(
    mission: Mission,
    fc: Forecast | None,
    robot: str,
    clock: MissionClock,
    t0: float,
    t1: float,
    step: float = 0.0,
    also: str | None = None,
) -> list[Bar]:
    """The robot's bars overlapping [t0, t1] (mission time): the log at its
    times, the rest predicted; with `step` (seconds per cell) one predicted bar
    per cell at most, and `also` (the selection) whatever the zoom."""
    out = _log_bars(mission.tasks.get(robot, []), clock, t0, t1)
    if fc is None:
        return out
    # the forecast's times are wall stamps: ask for the window in wall time
    w0, w1 = clock.to_ts(t0), clock.to_ts(t1)
    shown = list(fc.window(robot, w0, w1, step / clock.speed))
    picked = _picked(fc, also, robot, w0, w1)
    if picked is not None and picked not in shown:
        shown.append(picked)
    return out + [_predicted(f, f.skill, clock) for f in shown if f.skill is not None]


def _picked(
    fc: Forecast, also: str | None, robot: str, w0: float, w1: float
) -> SkillForecast | None:
    """The selected skill's prediction, when it is the robot's and overlaps
    [w0, w1] (wall time): shown whatever the zoom."""
    picked = fc.skill(also) if also is not None else None
    if picked is None or picked.robot != robot or picked.end < w0 or picked.start > w1:
        return None
    return picked


def _log_bars(task: list[SkillInstance], clock: MissionClock, t0: float, t1: float) -> list[Bar]:
    """The finished skills (the head of the list) at their actual times."""
    out: list[Bar] = []
    for s in task:
        if s.status not in FINISHED:
            break
        if s.started_at is None or s.finished_at is None:
            continue
        a, b = clock.of(s.started_at), clock.of(s.finished_at)
        if b >= t0 and a <= t1:
            out.append(Bar(s.id, a, b, s.status, _label(s), a, None, ()))
    return out


def _predicted(f: SkillForecast, s: SkillInstance, clock: MissionClock) -> Bar:
    at = clock.of_ts
    out = _spans(f.out_of_coverage, clock)
    return Bar(f.id, at(f.start), at(f.end), s.status, _label(s), at(f.ready), f.barrier, out)


def first_start(mission: Mission | None, clock: MissionClock, now: float) -> float:
    """When the first skill started (mission time: the log is the head of
    each list), or `now` when none has."""
    heads = [task[0] for task in mission.tasks.values() if task] if mission else []
    return min([now, *(clock.of(s.started_at) for s in heads if s.started_at)])


def times(
    mission: Mission, fc: Forecast | None, sid: str, clock: MissionClock
) -> tuple[float, float] | None:
    """(start, end) of a skill in mission time: actual for the log, else predicted."""
    found = mission.find(sid)
    if found is None:
        return None
    s = found[2]
    if s.status in FINISHED:
        if s.started_at is None or s.finished_at is None:
            return None
        return clock.of(s.started_at), clock.of(s.finished_at)
    f = fc.skill(sid) if fc is not None else None
    return (clock.of_ts(f.start), clock.of_ts(f.end)) if f is not None else None


# -- one lane ------------------------------------------------------------------------------


def _out_at(bar: Bar, t: float) -> bool:
    return any(a <= t < b for a, b in bar.out)


def lane(
    bars_: Iterable[Bar],
    win: Window,
    now: float,
    reach: float,
    *,
    selected: str | None = None,
    critical: frozenset[str] = frozenset(),
) -> list[Cell]:
    """A robot's line: the link-delay band up to `reach`, bars, waits, now."""
    w = win.width
    cells: list[Cell] = [(" ", ())] * w
    for x in range(max(0, win.col(now)), min(w, win.col(reach))):
        cells[x] = ("·", ("delay",))
    for bar in bars_:
        _wait(cells, win, bar)
        _bar(cells, win, bar, selected == bar.id, bar.id in critical)
    x = win.col(now)
    if 0 <= x < w and cells[x][0] in (" ", "·", "┄"):
        cells[x] = ("│", ("now",))
    return cells


def _wait(cells: list[Cell], win: Window, bar: Bar) -> None:
    if bar.start - bar.ready < win.dt / 2:
        return
    for x in range(max(0, win.col(bar.ready)), min(win.width, win.col(bar.start))):
        cells[x] = ("┄", ("wait",))


def _bar(cells: list[Cell], win: Window, bar: Bar, selected: bool, critical: bool) -> None:
    x0 = win.col(bar.start)
    x1 = max(x0 + 1, math.ceil((bar.end - win.t0) / win.dt))
    # the selected bar is drawn in the cursor's colours (its glyph still says its status)
    styles: tuple[str, ...] = ("cursor",) if selected else (STATUS_CSS[bar.status],)
    if critical:
        styles += ("critical",)
    # the label leaves the bar's last cell blank (if it has three or more): bars stay apart
    room = min(len(bar.label), x1 - x0 - 1 if x1 - x0 > 2 else x1 - x0)
    for x in range(max(0, x0), min(win.width, x1)):
        k = x - x0
        ch = bar.label[k] if k < room else " "
        own = styles
        if bar.out and _out_at(bar, win.t0 + (x + 0.5) * win.dt):
            own = (*styles, "hatch")
            if ch == " ":
                ch = "╱"
        cells[x] = (ch, own)


def links(lanes: dict[str, list[Bar]], order: list[str], win: Window) -> dict[int, set[int]]:
    """Spacer line i (below lane i) -> the columns where a barrier link crosses it."""
    out: dict[int, set[int]] = {}
    for members in _barrier_starts(lanes, order, win).values():
        x = members[0][1]
        if len(members) < 2 or not 0 <= x < win.width:
            continue
        rows = [r for r, _ in members]
        for spacer in range(min(rows), max(rows)):
            out.setdefault(spacer, set()).add(x)
    return out


def _barrier_starts(
    lanes: dict[str, list[Bar]], order: list[str], win: Window
) -> dict[str, list[tuple[int, int]]]:
    """Barrier -> the (lane, column) where each of its skills' bars starts."""
    where: dict[str, list[tuple[int, int]]] = {}
    for i, robot in enumerate(order):
        for bar in lanes.get(robot, []):
            if bar.barrier is not None:
                where.setdefault(bar.barrier, []).append((i, win.col(bar.start)))
    return where


def spacer(columns: set[int], width: int) -> list[Cell]:
    cells: list[Cell] = [(" ", ())] * width
    for x in columns:
        cells[x] = ("┆", ("link",))
    return cells


def planned(cells: list[Cell], spans: Iterable[tuple[float, float]], win: Window) -> list[Cell]:
    """A lane's spacer with the skills as planned when synchronized (▔, just
    under the bars of what happened); barrier links stay on top."""
    out = list(cells)
    for a, b in spans:
        x1 = max(win.col(a) + 1, math.ceil((b - win.t0) / win.dt))
        for x in range(max(0, win.col(a)), min(win.width, x1)):
            if out[x][0] == " ":
                out[x] = ("▔", ("planned",))
    return out


# -- the time axis ------------------------------------------------------------------------------


def axis(win: Window, now: float, clock: MissionClock) -> tuple[list[Cell], list[Cell]]:
    """Two lines: tick labels (mission time), then tick marks with `now` (▼)."""
    step = next((s for s in TICKS if s / win.dt >= LABEL_CELLS), TICKS[-1])
    labels: list[Cell] = [(" ", ())] * win.width
    marks: list[Cell] = [("─", ("axis",))] * win.width
    t = math.ceil(win.t0 / step) * step
    while t < win.t1:
        x = win.col(t)
        if 0 <= x < win.width:
            marks[x] = ("┬", ("axis",))
            for k, ch in enumerate(clock.time_text(t, seconds=step < 60)):
                if x + k < win.width:
                    labels[x + k] = (ch, ("axis-label",))
        t += step
    x = win.col(now)
    if 0 <= x < win.width:
        marks[x] = ("▼", ("now",))
    return labels, marks


# -- words ---------------------------------------------------------------------------------------


def _pct(x: float | None) -> str:
    return "?" if x is None else f"{max(0.0, x) * 100:.0f}%"


def details(mission: Mission, fc: Forecast | None, sid: str | None, clock: MissionClock) -> str:
    """The selected skill in a line: times, wait, battery, coverage (mission time)."""
    found = mission.find(sid) if sid is not None else None
    if found is None:
        return "no skill selected"
    robot, _, s = found
    head = f"{robot} · {GLYPHS[s.status]} {s.id} {skill_title(s)}"
    span = times(mission, fc, s.id, clock)
    if span is None:
        why = "never: held at a barrier that is never passed" if s.status not in FINISHED else "-"
        return f"{head} · {why}"
    when = f"{clock.time_text(span[0])}–{clock.time_text(span[1])}"
    f = fc.skill(s.id) if fc is not None and s.status not in FINISHED else None
    more = _forecast_words(f, clock) if f is not None else []
    return " · ".join([head, f"{clock.unit_prefix}{when}", *more])


def _forecast_words(f: SkillForecast, clock: MissionClock) -> list[str]:
    """What the forecast adds: the barrier wait, the battery, time out of coverage."""
    parts = []
    if f.wait_s >= 1:
        parts.append(f"waits {clock.duration_text(f.wait_s)} at {f.barrier}")
    if f.battery_start is not None:
        parts.append(f"battery {_pct(f.battery_start)}→{_pct(f.battery_end)}")
    if f.out_of_coverage:
        out = sum(b - a for a, b in f.out_of_coverage)
        parts.append(f"{clock.duration_text(out)} out of coverage")
    return parts


def fmt_step(dt: float) -> str:
    """A zoom level in words: '5 s', '2 min', '1 h'."""
    if dt < 60:
        return f"{dt:g} s"
    if dt < 3600:
        return f"{dt / 60:g} min"
    return f"{dt / 3600:g} h"


def nearest(
    mission: Mission, fc: Forecast | None, task: list[SkillInstance], at: float, clock: MissionClock
) -> str:
    """The skill of `task` running at `at`, else the one starting nearest to it."""
    best, best_d = task[0].id, math.inf
    for s in task:
        span = times(mission, fc, s.id, clock)
        if span is None:
            continue
        if span[0] <= at <= span[1]:
            return s.id
        d = min(abs(span[0] - at), abs(span[1] - at))
        if d < best_d:
            best, best_d = s.id, d
    return best
