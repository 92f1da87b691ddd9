"""The schedule's columns and how their lines are drawn (Rich segments).

A `Column` is one robot's part of the schedule: which skill (or progress line)
each of its lines shows. The functions here draw one line of a column from
the model and the widget's styles; the widget (console/widgets/schedule.py)
decides which lines to draw and where the cursor is.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from rich.cells import cell_len, set_cell_size
from rich.segment import Segment
from rich.style import Style
from textual.strip import Strip

from backend.core.contingency import after_tags, awaited_by
from backend.core.model import ACTIVE, SkillInstance, Status
from backend.core.plan.checks import Finding
from backend.protocol.messages import RobotInfo, Telemetry
from console.state import link
from console.state.contact import CONTACT_GLYPH, header_contact, out_of_contact
from console.state.freshness import FRESH, Freshness
from console.state.model import ConsoleModel
from console.state.nowcast import battery_now, probably_doing
from console.state.team import retired
from console.state.text import GLYPHS, STATUS_CSS, STATUS_WORDS, fmt_duration, skill_title

HEADER_H = 4  # name + presence / battery + link / activity / rule
MIN_W = 18  # a dynamic robot's column, at least (at 80 columns 3 robots and a static one fit)

Styles = dict[str, Style]  # component class without "schedule--" (and "base") -> style


@dataclass
class Column:
    robot: str
    static: bool
    x: int = 0
    width: int = MIN_W
    # synchronized section: (index in the task, "row" | "progress")
    sync: list[tuple[int, str]] = field(default_factory=list)
    idle: list[int] = field(default_factory=list)
    ids: list[str] = field(default_factory=list)
    line_of: dict[str, int] = field(default_factory=dict)  # filled by the layout
    # what each line of a section shows (id, kind, revision): comparing two
    # builds tells which lines a change touched, so only those are repainted
    # (the last: the pending command shown on the row, "" when none)
    # (and last, the row's tags: an after's partner changes them, not the skill's rev)
    sync_keys: list[tuple[str, str, int, str, str]] = field(default_factory=list)
    idle_keys: list[tuple[str, int, str, str]] = field(default_factory=list)

    def resting_id(self) -> str | None:
        """Where the cursor goes in this column: the first unsynchronized
        skill, else the last one (the active one), None when it has none."""
        if self.idle:
            return self.ids[self.idle[0]]
        return self.ids[-1] if self.ids else None

    def place_lines(self, sync_h: int) -> None:
        """Where each skill's row is (`line_of`), the plan starting under the divider."""
        self.line_of = {}
        for line, (i, kind) in enumerate(self.sync):
            if kind == "row":
                self.line_of[self.ids[i]] = line
        for k, i in enumerate(self.idle):
            self.line_of[self.ids[i]] = sync_h + 1 + k

    def line_key(self, line: int, sync_h: int) -> object:
        """What a content line shows (compared, never drawn)."""
        if line < sync_h:
            return _section_key(self.sync_keys, line, bool(self.sync))
        if line == sync_h:
            return "divider"
        return _section_key(self.idle_keys, line - sync_h - 1, bool(self.idle))


def _section_key(keys: Sequence[object], k: int, filled: bool) -> object:
    """What the k-th line of a section shows: a skill's key, else a blank
    line or, first in an empty section, its hint."""
    if k < len(keys):
        return keys[k]
    return "blank" if k or filled else "hint"


def build_column(model: ConsoleModel, robot: str, static: bool) -> Column:
    """A robot's column: its synchronized section (a row per skill, and a
    progress line under an active or failed one) and its plan, with the keys
    that tell which lines a later build changed."""
    col = Column(robot=robot, static=static)
    for i, s in enumerate(model.task(robot)):
        col.ids.append(s.id)
        c = model.uplinking(s.id)
        up = f"{c.id} {c.state}" if c is not None else ""  # its row shows the command
        tag = row_tag(model, s)
        if s.status == Status.IDLE:
            col.idle.append(i)
            col.idle_keys.append((s.id, s.rev, up, tag))
        else:
            col.sync.append((i, "row"))
            col.sync_keys.append((s.id, "row", s.rev, up, tag))
            if _has_progress_line(s):
                col.sync.append((i, "progress"))
                col.sync_keys.append((s.id, "progress", s.rev, "", ""))
    return col


def _has_progress_line(s: SkillInstance) -> bool:
    """An active skill has a line under its row (its progress, what it waits
    for), a failed one when it says why."""
    return s.status in ACTIVE or (s.status == Status.FAILURE and bool(s.status_info))


class _Awaited:
    """Skill id -> the skills that start after it, for the mission at one revision."""

    def __init__(self) -> None:
        self.mission: object = None
        self.revision = -1
        self.index: dict[str, list[str]] = {}

    def of(self, model: ConsoleModel) -> dict[str, list[str]]:
        m = model.mission
        if m is None:
            return {}
        if m is not self.mission or m.revision != self.revision:
            self.mission, self.revision, self.index = m, m.revision, awaited_by(m)
        return self.index


_AWAITED = _Awaited()


def row_tag(model: ConsoleModel, s: SkillInstance) -> str:
    """A row's tags: its barrier '[b1]', both ends of an after ('⇠lander-1' on
    the waiting row, '⇢lru2-4' on the awaited one)."""
    bid = model.barrier_of(s.id)
    tags = [f"[{bid}]"] if bid else []
    return " ".join(tags + after_tags(s.policies, _AWAITED.of(model).get(s.id, [])))


def fit(text: str, width: int) -> str:
    """Exactly `width` cells: truncated with an ellipsis, or padded."""
    if width <= 0:
        return ""
    if cell_len(text) > width:
        return set_cell_size(text, width - 1) + "…"
    return set_cell_size(text, width)


def fit_middle(text: str, width: int) -> str:
    """Exactly `width` cells, cut in the middle when too long: labels often
    differ at the end ("drive to POI-A" / "drive to POI-B"), so both ends stay
    ("explore…plain"); the editor shows the whole label."""
    if width <= 0:
        return ""
    if cell_len(text) <= width:
        return set_cell_size(text, width)
    if width < 6:
        return fit(text, width)
    start = set_cell_size(text, (width - 1) // 2 + (width - 1) % 2).rstrip()
    room = width - 1 - cell_len(start)
    k = room
    end = ""
    while 0 < k < len(text) - len(start):  # the tail's room filled, no space first
        end = text[-k:].lstrip()
        if cell_len(end) >= room:
            break
        k += 1
    while cell_len(end) > room:
        end = end[1:]
    return set_cell_size(start + "…" + end, width)


def click_hit(
    columns: list[Column], x: int, y: int, scroll_y: int
) -> tuple[int, str | None] | None:
    """(column, skill) a click at content x, screen row y hits: a header
    gives the column's resting skill; None: no column there."""
    for i, col in enumerate(columns):
        if col.x <= x < col.x + col.width + 1:
            if y < HEADER_H:
                return i, col.resting_id()
            line = scroll_y + y - HEADER_H
            return i, next((sid for sid, ln in col.line_of.items() if ln == line), None)
    return None


def hidden_robots(columns: list[Column], x0: int, x1: int) -> tuple[int, int]:
    """(columns cut or hidden left of x0, right of x1)."""
    left = sum(1 for c in columns if c.x < x0)
    right = sum(1 for c in columns if c.x + c.width > x1)
    return left, right


def with_hidden_robots(strip: Strip, hidden: tuple[int, int], width: int, style: Style) -> Strip:
    """The rule under the headers says how many robots are off to each side
    ("← 1", "+2 robots →"): a scrollbar alone is easy to miss."""
    left, right = hidden
    if right:
        text = f" +{right} robot{'s' if right > 1 else ''} → " if width >= 40 else f" +{right}→"
        n = cell_len(text)
        strip = Strip.join([strip.crop(0, width - n), Strip([Segment(text, style)])])
    if left:
        text = f" ← {left} " if width >= 40 else f"←{left}"
        strip = Strip.join([Strip([Segment(text, style)]), strip.crop(cell_len(text), width)])
    return strip


# -- the header: a table of its lines ----------------------------------------------------


@dataclass(frozen=True)
class Head:
    """What a column's header lines are drawn from."""

    model: ConsoleModel
    col: Column
    st: Styles
    compact: bool  # a static robot's narrow column (not expanded)
    selected: bool  # the cursor's column: its rule is heavy
    fresh: Freshness = FRESH  # stale: the robot's last known state, drawn as such


def _offline_since(robot: str, clock: str, width: int) -> str:
    """The longest way to say since when a robot is offline that fits beside its name."""
    for p in (f"✕ offline since {clock}", f"✕ offline {clock}", f"✕ off {clock}", f"✕ {clock}"):
        if cell_len(robot) + 1 + cell_len(p) <= width:
            return p
    return "✕ off"


def _presence(h: Head) -> tuple[str, Style]:
    """The robot's presence and its style (a compact column: only the glyph)."""
    if retired(h.model, h.col.robot):  # no new syncs; its plan awaits "give to…"
        return ("⊘" if h.compact else "⊘ retired"), h.st["offline"]
    info = h.model.robots.get(h.col.robot)
    if info is None:
        pres, pst = "? unknown", h.st["unknown"]
    elif info.online:
        pres, pst = _online(h, info)
    else:
        pres, pst = _offline(h, info), h.st["offline"]
    if h.compact:
        pres = pres[0] if info is not None and info.online else "✕"
    return pres, pst


def _online(h: Head, info: RobotInfo) -> tuple[str, Style]:
    """An online robot's contact ('● online'; never so while its window is closed)."""
    said = header_contact(info, h.model.clock, h.col.width - cell_len(h.col.robot) - 1)
    if out_of_contact(info):
        return said or CONTACT_GLYPH, h.st["stale-head"]
    return said or "● online", h.st["online"]


def _offline(h: Head, info: RobotInfo) -> str:
    """'✕ offline', since when if known, as it fits beside the name."""
    if info.since is None:
        return "✕ offline"
    return _offline_since(h.col.robot, h.model.clock.stamp_text(info.since), h.col.width)


def _name_line(h: Head) -> list[Segment]:
    w = h.col.width
    pres, pst = _presence(h)
    name_w = max(1, w - cell_len(pres) - 1)
    return [
        Segment(fit(h.col.robot, name_w), h.st["robot"]),
        Segment(" ", h.st["base"]),
        Segment(fit(pres, w - name_w - 1), pst),
    ]


def _levels_line(h: Head) -> list[Segment]:
    """Battery, the link's words (pending commands, delay), link quality:
    as many as fit, in that order."""
    w, st = h.col.width, h.st
    if h.compact:
        return [Segment(fit("static", w), st["dim"])]
    t = h.model.telemetry.get(h.col.robot)
    gap = st["base"]
    if t is None:
        bat, link, gap = ("bat –", st["dim"]), ("link –", st["dim"]), st["dim"]
    elif h.fresh.stale:  # the last levels heard, not live ones (and the now-cast's)
        now = battery_now(h.model, h.col.robot, t.battery)  # the now-cast's, if it differs
        bat = (f"bat {t.battery:.0%} {now}".rstrip(), st["stale"])
        link = (f"link {int(round(t.link * 100))}%", st["stale"])
        gap = st["stale"]
    else:
        bst = st["battery-low"] if t.battery < 0.2 else st["base"]
        bat = (f"bat {int(round(t.battery * 100))}%", bst)
        link = (
            (f"link {int(round(t.link * 100))}%", st["base"])
            if t.in_range
            else ("link: out of range", st["offline"])
        )
    return _spread([bat, *_link_words(h), link], w, gap)


def _link_words(h: Head) -> list[tuple[str, Style]]:
    """'⇡2 1m10s' (commands waiting for the robot's answer), '⇄20s' (delay)."""
    robot, st = h.col.robot, h.st
    out = []
    pending = link.pending_text(h.model.pending(robot), h.model.clock)
    if pending:
        out.append((pending, st["tag"]))
    delay = link.delay_text(link.robot_delay_s(h.model.robots, robot), h.model.clock)
    if delay:
        out.append((delay, st["dim"]))
    return out


def _spread(parts: list[tuple[str, Style]], width: int, base: Style) -> list[Segment]:
    """Parts two spaces apart in `width` cells, as many as fit (`_fitting`)."""
    shown = _fitting(parts, width)
    segs: list[Segment] = []
    for i, (text, style) in enumerate(shown):
        if i:
            segs.append(Segment("  ", base))
        segs.append(Segment(fit(text, width) if cell_len(text) > width else text, style))
    used = sum(cell_len(seg.text) for seg in segs)
    return [*segs, Segment(" " * max(0, width - used), shown[-1][1])]


def _fitting(parts: list[tuple[str, Style]], width: int) -> list[tuple[str, Style]]:
    """Parts in order of importance: the last ones cut to the room left (8
    cells at least: a word and its value) or left out until the rest fits."""

    def total(ps: list[tuple[str, Style]]) -> int:
        return sum(cell_len(p) for p, _ in ps) + 2 * (len(ps) - 1)

    shown = list(parts)
    while len(shown) > 1 and total(shown) > width:
        room = width - total(shown[:-1]) - 2
        if room >= 8:
            shown[-1] = (fit(shown[-1][0], room), shown[-1][1])
            break
        shown.pop()
    return shown


def _activity_line(h: Head) -> list[Segment]:
    if h.compact:
        return _skill_count(h)
    activity = h.model.activity_text(h.col.robot)
    if h.fresh.stale:
        return _stale_activity(h, activity)
    return [Segment(fit(activity, h.col.width), h.st["dim"])]


def _skill_count(h: Head) -> list[Segment]:
    """A compact column's activity line: how many skills (as of when, if stale)."""
    if h.fresh.stale:
        return [Segment(fit(h.fresh.as_of(), h.col.width), h.st["stale-head"])]
    n = len(h.col.ids)
    return [Segment(fit(f"{n} skill{'s' if n != 1 else ''}", h.col.width), h.st["dim"])]


def _stale_activity(h: Head, activity: str) -> list[Segment]:
    """As of when: first, so it is never cut; then what the robot probably
    does now (the now-cast), else what it was doing then."""
    w = h.col.width
    ago = h.fresh.ago()
    as_of = fit(ago, w) if cell_len(ago) > w else ago
    probably = probably_doing(h.model, h.col.robot)
    rest = fit(f" {probably}" if probably else f": {activity}", w - cell_len(as_of))
    return [Segment(as_of, h.st["stale-head"]), Segment(rest, h.st["stale"])]


def _rule_line(h: Head) -> list[Segment]:
    return [Segment(("━" if h.selected else "─") * h.col.width, h.st["rule"])]


HEADER_LINES: tuple[Callable[[Head], list[Segment]], ...] = (
    _name_line,
    _levels_line,
    _activity_line,
    _rule_line,
)
assert len(HEADER_LINES) == HEADER_H


# -- content lines ---------------------------------------------------------------------------


def skill_segments(
    s: SkillInstance,
    width: int,
    st: Styles,
    *,
    marked: bool,
    draft: bool,
    tag: str,
    extra: str,
    cursor: Style | None,
    check: Finding | None = None,
    stale: bool = False,
    uplink: str = "",
) -> list[Segment]:
    """A skill's row: mark, glyph, title (*: unapplied edits), attempt, the
    parameter summary where it fits, the barrier tag, the plan checks' glyph
    (✖ error, ⚠ warning, ≈ waived); on `cursor`'s background. `stale`: a
    synchronized skill of a robot not heard lately (its last known status).
    `uplink`: a pending command concerns it ('sync #17 sent 40s'): ⇡ and that
    text instead of the parameter summary."""
    sst = st[STATUS_CSS[s.status]] + st["stale"] if stale else st[STATUS_CSS[s.status]]
    end, end_w = _row_end(tag, check, st)
    segs = [
        Segment("+", st["mark"]) if marked else Segment(" ", st["base"]),
        Segment(link.UPLINK_GLYPH, st["tag"]) if uplink else Segment(GLYPHS[s.status], sst),
    ]
    title = ("*" if draft else "") + skill_title(s)
    segs += _title_and_summary(title, s.attempt, uplink or extra, width - 2 - end_w, sst, st)
    segs += end
    return segs if cursor is None else _on_cursor(segs, cursor)


def _title_and_summary(
    title: str, attempt_n: int, extra: str, room: int, sst: Style, st: Styles
) -> list[Segment]:
    """The title and attempt in `room` cells, and `extra` (the summary) in what they leave."""
    attempt = f" #{attempt_n}" if attempt_n > 1 else ""
    body = " " + title + attempt
    rest = room - cell_len(body)
    if rest <= 0:  # the label is cut in the middle, never the attempt number
        return [Segment(" " + fit_middle(title, room - 1 - len(attempt)) + attempt, sst)]
    if extra and rest >= 8:  # a summary cut to a letter or two says nothing
        return [Segment(body, sst), Segment(fit(" " + extra, rest), st["dim"])]
    return [Segment(body, sst), Segment(" " * rest, st["base"])]


def _row_end(tag: str, check: Finding | None, st: Styles) -> tuple[list[Segment], int]:
    """The row's end and its cells: the tags, then the plan checks' glyph."""
    end: list[Segment] = []
    cells = 0
    if tag:
        tag = f"{tag} " if check is not None else tag
        end += [Segment(" ", st["base"]), Segment(tag, st["tag"])]
        cells = cell_len(tag) + 1
    if check is not None:
        end.append(Segment(*_check_glyph(check, st)))
        cells += 1
    return end, cells


def _on_cursor(segs: list[Segment], cursor: Style) -> list[Segment]:
    """A row under the cursor: each segment on the cursor's background."""
    return [Segment(seg.text, (seg.style or Style()) + cursor) for seg in segs]


def _check_glyph(f: Finding, st: Styles) -> tuple[str, Style]:
    if f.waiver is not None:
        return "≈", st["check-waived"]
    return ("✖", st["check-error"]) if f.severity == "error" else ("⚠", st["check-warning"])


def progress_segments(
    model: ConsoleModel, col: Column, s: SkillInstance, st: Styles, fresh: Freshness = FRESH
) -> list[Segment]:
    """The line under an active (or failed) skill: its progress bar and ETA,
    why it paused or failed, what a barrier waits for. A stale robot's bar
    stops where it was last heard, without an ETA."""
    w = col.width
    t = model.telemetry.get(col.robot)
    pct = t.progress if t is not None and t.skill == s.id else None
    if fresh.stale and s.status in (Status.RUNNING, Status.PAUSED):
        return _stale_progress(pct, w, st, fresh)
    said = _SAID_UNDER.get(s.status)
    if said is not None:
        return said(model, s, pct, w, st)
    return _running(t, pct, s.status_info, w, st, fresh)


def _running(
    t: Telemetry | None, pct: float | None, info: str, w: int, st: Styles, fresh: Freshness
) -> list[Segment]:
    """A running skill's bar and ETA; without telemetry of it, 'running'."""
    if t is None or pct is None:
        text = "   running" + (f" · {info}" if info else "")
        return [Segment(fit(text, w), st["dim"])]
    # telemetry comes on change: the ETA counts down from the last sample (as old as `fresh`)
    eta_s = max(0.0, t.eta_s - (fresh.age_s or 0.0)) if t.eta_s is not None else None
    return _progress_bar(pct, eta_s, w, st)


_Under = Callable[[ConsoleModel, SkillInstance, float | None, int, Styles], list[Segment]]


def _failed(
    model: ConsoleModel, s: SkillInstance, pct: float | None, w: int, st: Styles
) -> list[Segment]:
    return [Segment(fit("   ↳ " + s.status_info, w), st["failure"])]


def _waiting(
    model: ConsoleModel, s: SkillInstance, pct: float | None, w: int, st: Styles
) -> list[Segment]:
    return [Segment(fit("   " + wait_text(model, s), w), st["synchwaiting"])]


def _paused(
    model: ConsoleModel, s: SkillInstance, pct: float | None, w: int, st: Styles
) -> list[Segment]:
    text = (
        "   paused"
        + (f" at {int(pct * 100)}%" if pct is not None else "")
        + (f" · {s.status_info}" if s.status_info else "")
    )
    return [Segment(fit(text, w), st["paused"])]


# the progress line of a skill that does not progress: why it failed, what it
# waits for, where it paused (a running skill's: its bar)
_SAID_UNDER: dict[Status, _Under] = {
    Status.FAILURE: _failed,
    Status.SYNCHWAITING: _waiting,
    Status.PAUSED: _paused,
}


def _progress_bar(pct: float, eta_s: float | None, w: int, st: Styles) -> list[Segment]:
    """`▕██░░▏ 45% ETA 2m12s` in `w` cells."""
    eta = fmt_duration(eta_s) if eta_s is not None else ""
    # the longest label that leaves the bar 4 cells ("45% ETA 2m12s", "45% 2m12s", "45%")
    labels = [f" {int(pct * 100):3d}%" + (f" ETA {eta}" if eta else "")]
    if eta:
        labels.append(f" {int(pct * 100)}% {eta}")
    labels.append(f" {int(pct * 100)}%")
    label = next((x for x in labels if w - 5 - cell_len(x) >= 4), labels[-1])
    bar_w = max(4, w - 3 - cell_len(label) - 2)
    filled = int(round(pct * bar_w))
    return [
        Segment("   ▕", st["dim"]),
        Segment("█" * filled, st["progress"]),
        Segment("░" * (bar_w - filled), st["dim"]),
        Segment("▏", st["dim"]),
        Segment(fit(label, w - 3 - bar_w - 2), st["base"]),
    ]


def _stale_progress(pct: float | None, w: int, st: Styles, fresh: Freshness) -> list[Segment]:
    """`▕██░░▏ 45% as of 25s ago`: the last known progress, stopped."""
    as_of = fresh.as_of()
    if pct is None:
        return [Segment(fit(f"   {as_of}", w), st["stale"])]
    label = f" {int(pct * 100)}% {as_of}"
    bar_w = w - 5 - cell_len(label)
    if bar_w < 4:
        return [Segment(fit(f"   {int(pct * 100)}% {as_of}", w), st["stale"])]
    filled = int(round(pct * bar_w))
    return [
        Segment("   ▕" + "█" * filled + "░" * (bar_w - filled) + "▏", st["stale"]),
        Segment(fit(label, w - 5 - bar_w), st["stale-head"]),
    ]


def wait_text(model: ConsoleModel, s: SkillInstance) -> str:
    """What a synchwaiting skill waits for: its barrier's partners, else the
    skill it starts after (policies.after)."""
    after = s.policies.after is not None  # waited for first, then its barrier
    if after and (model.barrier_of(s.id) is None or s.status_info.startswith("after ")):
        return after_wait_text(model, s)
    return barrier_wait_text(model, s)


def after_wait_text(model: ConsoleModel, s: SkillInstance) -> str:
    """'after lander-1: lander OFFLINE 12:30', '…: lander out of contact', the
    robot's own words when it says it cannot reach its partner, else what the
    other skill is doing."""
    sid = str(s.policies.after)
    robot = model.owner(sid)
    if robot is None:
        return s.status_info or f"after {sid}"
    offline = _offline_text(model, robot)
    if offline:
        return f"after {sid}: {offline}"
    if "unreachable" in s.status_info or "offline" in s.status_info:
        return s.status_info  # the waiting robot cannot reach it (its radio, the network)
    return f"after {sid}: {_partner_doing(model, robot, sid)}"


def _offline_text(model: ConsoleModel, robot: str) -> str:
    """'lander OFFLINE 12:30' (since when, if known); '' while it is online."""
    info = model.robots.get(robot)
    if info is not None and info.online:
        return ""
    since = f" {model.clock.stamp_text(info.since)}" if info and info.since else ""
    return f"{robot} OFFLINE{since}"


def _partner_doing(model: ConsoleModel, robot: str, sid: str) -> str:
    if out_of_contact(model.robots.get(robot)):
        return f"{robot} out of contact"
    found = model.find(sid)
    return f"waiting for {robot} ({STATUS_WORDS[found[2].status] if found else 'unknown'})"


def barrier_wait_text(model: ConsoleModel, s: SkillInstance) -> str:
    """What a robot waiting at a barrier waits for; offline partners first."""
    bid = model.barrier_of(s.id)
    if bid is None or model.mission is None:
        return s.status_info or "waiting at a barrier"
    offline, waiting = _absent(model, model.mission.barriers[bid].skills, s.id)
    if offline:
        return f"{bid}: " + ", ".join(offline)
    if waiting:
        return f"{bid}: waiting for " + ", ".join(waiting)
    return f"{bid}: all partners ready"


def _absent(model: ConsoleModel, skills: list[str], own: str) -> tuple[list[str], list[str]]:
    """A barrier's partners not there: the offline ones ('lander OFFLINE
    12:30'), the robots whose skill has not reached it yet."""
    offline: list[str] = []
    waiting: list[str] = []
    for sid in skills:
        robot = model.owner(sid)
        if sid == own or robot is None:
            continue
        said = _offline_text(model, robot)
        if said:
            offline.append(said)
        elif not _arrived(model, sid):
            waiting.append(robot)
    return offline, waiting


def _arrived(model: ConsoleModel, sid: str) -> bool:
    """Whether a partner's skill waits at the barrier (or is gone: nothing to wait for)."""
    found = model.find(sid)
    return not found or found[2].status == Status.SYNCHWAITING
