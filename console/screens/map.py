"""The map screen (app mode "map"): the site, robots, markers and goals.

Layout: top bar / map | legend / info line (cursor, selection, feed) /
status line / footer. Marker edits and parameter picks go through the same
operations as everywhere (backend.core.ops, submitted by the screen), done by
the objects it owns (map_markers.py, map_params.py); the "selected skill" is
the schedule's cursor on the mission screen.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from rich.text import Text
from textual import events, on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal
from textual.screen import Screen
from textual.signal import Signal
from textual.widgets import Footer, Static

from backend.core.model import Status, on_board_text
from console.bindings import bind, bindings, key_names
from console.messages import HelpRequested
from console.operations import OperationService
from console.screens.map_markers import MarkerActions
from console.screens.map_params import ParamActions
from console.state.actions import ACTIONS
from console.state.changes import StateChange, Topic
from console.state.contact import CONTACT_GLYPH
from console.state.keys import KeyNames
from console.state.markers import marker_point, marker_use
from console.state.model import ConsoleModel
from console.state.nowcast import NOWCAST_GLYPH
from console.state.site import here_text
from console.state.text import GLYPHS, STATUS_CSS, STATUS_WORDS
from console.widgets.bars import InfoLine, StatusLine, TopBar, connection_text
from console.widgets.map.view import (
    AREA_GLYPH,
    BOX_GLYPH,
    FOLLOW_GLYPH,
    GOAL_GLYPH,
    LANDER_GLYPH,
    NO_LINK_GLYPH,
    NOWCAST_ARROWS,
    POSE_ARROWS,
    POSITION_GLYPH,
    ROBOT_ARROWS,
    RSS_GLYPH,
    STONE_GLYPH,
    MapView,
)

# this module's look (CSS_PATH); absolute, so a subclass defined elsewhere finds it too
TCSS = Path(__file__).with_name("map.tcss")

NO_FEED = "no map feed — is the simulator running?"
TURN = math.radians(15)
LEGEND_MIN_WIDTH = 100


LEGEND_STATUSES = (
    Status.RUNNING,
    Status.PAUSED,
    Status.SYNCHWAITING,
    Status.FAILURE,
    Status.IDLE_SYNCHRONIZED,
    Status.IDLE,
)


def _fg(c: dict[str, str], var: str) -> str:
    """A glyph in a theme colour (bold: as on the map)."""
    return f"bold {c[var]}" if var in c else "bold"


def _bg(c: dict[str, str], var: str, default: str = "") -> str:
    """A ground's background colour."""
    return f"on {c[var]}" if var in c else default


def _legend_rows(c: dict[str, str], keys: KeyNames) -> list[tuple[str, str, str]]:
    """(glyph, style, what) of the legend, below the robots' heading."""
    statuses = [
        (GLYPHS[st], _fg(c, f"status-{STATUS_CSS[st]}"), f"  {STATUS_WORDS[st]}")
        for st in LEGEND_STATUSES
    ]
    return [
        *statuses,
        ("✕", _fg(c, "presence-offline"), "  offline"),
        (CONTACT_GLYPH, _fg(c, "presence-unknown"), "  out of contact"),
        (NOWCAST_ARROWS[0], _fg(c, "presence-unknown"), f"{NOWCAST_GLYPH} probably now"),
        (NO_LINK_GLYPH, _fg(c, "presence-offline"), "  out of comms range"),
        (FOLLOW_GLYPH, "bold", f"  followed ({keys.say('map.follow')})"),
        (POSE_ARROWS[0], "bold", "pose marker"),
        (POSITION_GLYPH, "bold", "position marker"),
        (AREA_GLYPH, "bold", "area marker"),
        ("●", _fg(c, "map-marker-active"), "  used on a robot"),
        ("○", _fg(c, "map-marker-bound"), "  used by idle skill"),
        (GOAL_GLYPH, _fg(c, "map-goal"), "goal of a skill"),
        (LANDER_GLYPH, _fg(c, "map-lander"), "lander"),
        (BOX_GLYPH, _fg(c, "map-box"), "payload box"),
        (RSS_GLYPH, _fg(c, "map-rss"), "sampling region"),
        (STONE_GLYPH, _fg(c, "map-stone"), "stone found"),
        ("·", _bg(c, "map-unknown"), "unexplored"),
        ("~", _bg(c, "map-sand"), "sand (slow)"),
        ("▴", _bg(c, "map-rock"), "rock (impassable)"),
        (" ", _bg(c, "map-link", "reverse"), "in comms range"),
        (POSE_ARROWS[0], _fg(c, "map-cursor"), "cursor (heading)"),
    ]


def legend_text(colours: dict[str, str] | None = None, keys: KeyNames | None = None) -> Text:
    """The legend; `colours` (theme variables) colour its glyphs like the map."""
    t = Text()

    def row(glyph: str, style: str, what: str) -> None:
        t.append(f" {glyph} ", style=style)
        t.append(f"{what}\n")

    t.append("Legend\n", style="bold")
    row(ROBOT_ARROWS[0], "bold", "robot, heading")
    # the one heading convention (the editor, ctl and the info line use it too)
    t.append("   heading: 0° east,\n   counter-clockwise\n", style="dim")
    for glyph, style, what in _legend_rows(colours or {}, keys or KeyNames()):
        row(glyph, style, what)
    return t


def map_top_text(m: ConsoleModel, keys: KeyNames) -> Text:
    """The map's top bar: the mission and revision, the connection, the way back."""
    t = Text()
    t.append("missionctl map", style="bold")
    if m.mission is not None:
        t.append(f"  {m.mission.name}", style="bold")
        t.append(f"  rev {m.mission.revision}", style="dim")
    t.append(f"   {connection_text(m.connection)}")
    t.append(f"   {keys.say('app.show_mission')} schedule", style="dim")
    return t


def _feed_note(model: ConsoleModel, v: MapView, feed_state: str) -> str:
    """Why there is no map (yet), or nothing when it is live."""
    if feed_state == "none":
        return model.map_note or NO_FEED
    if v.mirror is None or not v.mirror.ready:
        return "waiting for the map feed…"
    return ""


def _selection_text(model: ConsoleModel, v: MapView, t: Text) -> None:
    """Who is followed, the selected marker and the schedule's selected skill."""
    if v.follow:
        t.append(f"  following {v.follow}", style="bold")
    if v.selected_marker:
        use = marker_use(model).get(v.selected_marker, "unused")
        t.append(f"  marker {v.selected_marker} ({use})")
        markers = model.mission.markers if model.mission is not None else {}
        t.append(on_board_text(markers.get(v.selected_marker), " "), style="italic")
    found = model.find(v.selected_skill)
    if found is not None:
        s = found[2]
        t.append(f"  skill {s.id} {s.skill} ({STATUS_WORDS[s.status]})", style="dim")


def info_text(model: ConsoleModel, v: MapView, feed_state: str) -> Text:
    """The info lines: the feed (when not live), the cursor and scale, who is
    followed, the selected marker and the schedule's selected skill; then what
    is under the cursor (console/state/site.py)."""
    t = Text()
    note = _feed_note(model, v, feed_state)
    if note:
        t.append(note, style="bold")
        t.append("  ")
    x, y = v.cursor
    t.append(f"cursor ({x:.1f}, {y:.1f}) heading {math.degrees(v.heading):.0f}°")
    t.append(f"  {v.vp.mpp:.2g} m/px", style="dim")
    _selection_text(model, v, t)
    here = here_text(v.mirror, model.mission, model.telemetry, x, y, tol=max(1.0, v.vp.mpp))
    t.append(f"\nhere: {here}")
    return t


def next_after(items: list[str], current: str | None) -> str | None:
    """The item after `current` (the first when it is none of them; None after the last)."""
    i = items.index(current) + 1 if current in items else 0
    return items[i] if i < len(items) else None


class Legend(Static):
    """The legend beside the map (hidden below LEGEND_MIN_WIDTH columns until toggled)."""


MAP_ACTIONS = {a.name for a in ACTIONS if a.scope == "map"}


class MapScreen(Screen):
    SCOPE = "map"  # its own palette entries (console/commands.py)
    BINDINGS = [
        *bindings("map"),
        Binding("up", "cursor(0, -1)", "Up", show=False),
        Binding("down", "cursor(0, 1)", "Down", show=False),
        Binding("left", "cursor(-1, 0)", "Left", show=False),
        Binding("right", "cursor(1, 0)", "Right", show=False),
        Binding("ctrl+up", "cursor(0, -8)", show=False),
        Binding("ctrl+down", "cursor(0, 8)", show=False),
        Binding("ctrl+left", "cursor(-8, 0)", show=False),
        Binding("ctrl+right", "cursor(8, 0)", show=False),
        bind("app.help", "help", show=True),
        Binding(
            "escape", "app.show_mission", "Schedule", show=False
        ),  # "back to the schedule" (help: App keys)
    ]
    CSS_PATH = TCSS

    def __init__(
        self, model: ConsoleModel, changes: Signal[StateChange], ops: OperationService
    ) -> None:
        super().__init__()
        self.model = model
        self.changes = changes
        self.ops = ops
        self.feed_state = "waiting"  # waiting | live | none
        self._topbar = TopBar(id="map-topbar")
        self.view = MapView(model, id="map")
        self._legend = Legend("", id="legend")
        self._info = InfoLine("", id="map-info")
        self._status = StatusLine("", id="map-status")
        self.message = ""
        self.legend_choice: bool | None = None  # None: by terminal width
        self.markers = MarkerActions(self)
        self.params = ParamActions(self)
        if model.map_update is not None:  # the feed (or its absence) came before the screen
            self.map_changed(model.map_mirror, model.map_update)

    def compose(self) -> ComposeResult:
        yield self._topbar
        with Horizontal(id="map-main"):
            yield self.view
            yield self._legend
        yield self._info
        yield self._status
        yield Footer()

    def on_mount(self) -> None:
        # a notification never covers the cursor: the view moves it clear
        self.screen_layout_refresh_signal.subscribe(
            self,
            lambda _s: self.view.uncover(self.query("Toast")),  # Textual's notifications
        )
        self._legend.update(legend_text(self.app.get_css_variables(), key_names(self)))
        self._apply_legend()
        self.view.focus()
        self.sync_selection()
        self.update_top()
        self.update_info()
        self.changes.subscribe(self, self.changed)

    def on_resize(self, event: events.Resize) -> None:
        self._apply_legend()
        if not self.view.fitted and (self.view.mirror is None or not self.view.mirror.ready):
            self.call_after_refresh(self.view.fit_known)

    def on_screen_resume(self) -> None:
        self.sync_selection()
        self.view.overlays_changed()
        self.update_top()
        self.update_info()

    def _apply_legend(self) -> None:
        show = self.legend_choice
        if show is None:
            show = self.app.size.width >= LEGEND_MIN_WIDTH
        self.set_class(not show, "-no-legend")

    # -- state in (the model's changes) ---------------------------------------------------------
    def changed(self, c: StateChange) -> None:
        if c.about(Topic.MAP):
            self.map_changed(self.model.map_mirror, c.map_update)
        if c.about(Topic.MISSION):  # marker events change no robot's column but the map
            self.model_changed()
        if c.about(Topic.TELEMETRY):
            self._robots_moved(c.robots or ())
        if c.about(Topic.FLEET):
            self.view.overlays_changed()
        if c.about(Topic.CONNECTION):
            self.update_top()

    def _robots_moved(self, robots: Iterable[str]) -> None:
        for robot in robots:
            self.view.robot_moved(robot)
            if self.view.follow == robot:
                self.update_info()

    def map_changed(self, mirror: Any, update: Any) -> None:
        kind = getattr(update, "kind", "snapshot")
        if kind == "none":
            self.feed_state = "none"
            if self.view.mirror is not None and not self.view.mirror.ready:
                self.view.set_mirror(None)
        elif kind == "snapshot" or self.view.mirror is not mirror:
            self.feed_state = "live"
            self.view.set_mirror(mirror)
        else:
            self.feed_state = "live"
            self.view.tiles_changed(update.tiles)
            if update.objects:
                self.view.overlays_changed()
        self.update_info()

    def model_changed(self) -> None:
        self.sync_selection()
        if self.view.selected_marker and (
            self.model.mission is None
            or self.view.selected_marker not in self.model.mission.markers
        ):
            self.view.selected_marker = None
        self.view.overlays_changed()
        self.update_top()
        self.update_info()

    def sync_selection(self) -> None:
        sid = self.model.selection.skill  # the schedule's cursor
        if sid != self.view.selected_skill:
            self.view.selected_skill = sid
            self.view.overlays_changed()

    # -- lines -------------------------------------------------------------------------------------
    def update_top(self) -> None:
        self._topbar.update(map_top_text(self.model, key_names(self)), layout=False)

    def update_info(self) -> None:
        self._info.update(info_text(self.model, self.view, self.feed_state), layout=False)
        self._info.set_class(self.feed_state == "none", "-nofeed")

    def say(self, text: str, severity: str = "info") -> None:
        self.message = text
        self._status.show(text, severity)

    @work(group="ops", exit_on_error=False)
    async def submit(self, op: Any, what: str, *, on_ok: Any = None, **kw: Any) -> None:
        """Submit `op`, await its outcome here; `on_ok(reply)` says what it did."""
        done = "" if on_ok is not None else None
        outcome = await self.ops.submit(op, what, say=self.say, done=done, **kw)
        if outcome.reply is not None and on_ok is not None:
            on_ok(outcome.reply)

    # -- actions: view -----------------------------------------------------------------------------
    def action_help(self) -> None:
        self.post_message(HelpRequested())

    def action_cursor(self, dcol: int, drow: int) -> None:
        self.view.move_cursor(dcol, drow)

    @on(MapView.CursorMoved)
    @on(MapView.Zoomed)
    def _cursor_moved(self) -> None:
        self.update_info()

    def action_map_zoom_in(self) -> None:
        self.view.zoom(0.5)
        self.update_info()

    def action_map_zoom_out(self) -> None:
        self.view.zoom(2.0)
        self.update_info()

    def action_map_fit(self) -> None:
        if self.view.mirror is None or not self.view.mirror.ready:
            self.say("no map yet: nothing to fit", "warning")
            return
        self.view.follow = None
        self.view.fit()
        self.view.set_cursor(self.view.vp.cx, self.view.vp.cy)  # back in the middle of it
        self.update_info()

    def _pan(self, dx: int, dy: int) -> None:
        self.view.follow = None
        self.view.pan(dx * max(1, self.view.vp.w // 4), dy * max(1, self.view.vp.h // 4))
        self.update_info()

    def action_map_pan_left(self) -> None:
        self._pan(-1, 0)

    def action_map_pan_right(self) -> None:
        self._pan(1, 0)

    def action_map_pan_up(self) -> None:
        self._pan(0, -1)

    def action_map_pan_down(self) -> None:
        self._pan(0, 1)

    def action_map_centre(self) -> None:
        self.view.follow = None
        self.view.set_view(cx=self.view.cursor[0], cy=self.view.cursor[1])
        self.update_info()

    def action_map_follow(self) -> None:
        robots = self._followable()
        if not robots:
            self.say("no robot position known yet (no telemetry): nothing to follow", "warning")
            return
        nxt = next_after(robots, self.view.follow)  # after the last one: nobody
        self.view.follow = nxt
        if nxt is None:
            self.say("stopped following")
        else:
            t = self.model.telemetry[nxt]
            self.view.set_view(cx=t.pose.x, cy=t.pose.y)
            again = key_names(self).say("map.follow")
            self.say(f"following {nxt} ({again}: next robot; moving the view stops it)")
        self.view.overlays_changed()
        self.update_info()

    def _followable(self) -> list[str]:
        """The robots that move and whose position is known, in the schedule's order."""
        m = self.model
        return [r for r in m.robot_order() if m.robot_kind(r) != "static" and r in m.telemetry]

    def action_map_turn_left(self) -> None:
        self.view.heading = (self.view.heading + TURN) % (2 * math.pi)
        self.view.overlays_changed()
        self.update_info()

    def action_map_turn_right(self) -> None:
        self.view.heading = (self.view.heading - TURN) % (2 * math.pi)
        self.view.overlays_changed()
        self.update_info()

    def action_map_legend(self) -> None:
        self.legend_choice = self.has_class("-no-legend")
        self._apply_legend()

    def action_map_next_marker(self) -> None:
        m = self.model.mission
        names = list(m.markers) if m is not None else []
        if not names:
            self.say("this mission has no markers: a adds one at the cursor", "warning")
            return
        cur = self.view.selected_marker
        name = names[(names.index(cur) + 1) % len(names)] if cur in names else names[0]
        self.select_marker(name)

    def select_marker(self, name: str) -> None:
        mk = self.model.mission.markers[name]
        self.view.selected_marker = name
        if mk.kind == "pose":
            self.view.heading = mk.pose.yaw
        self.view.set_cursor(*marker_point(mk))
        self.say(
            f"marker {name} ({mk.kind}){': ' + mk.description if mk.description else ''}"
            + on_board_text(mk, "; ")
        )
        self.update_info()

    # -- actions: markers (map_markers.py) and parameters (map_params.py) ------------------
    @work(group="dialog")
    async def action_map_add_marker(self) -> None:
        await self.markers.add()

    def action_map_move_marker(self) -> None:
        self.markers.move()

    @work(group="dialog")
    async def action_map_rename_marker(self) -> None:
        await self.markers.rename()

    @work(group="dialog")
    async def action_map_delete_marker(self) -> None:
        await self.markers.delete()

    def action_map_bind(self) -> None:
        marker = self.markers.selected()
        if marker is not None:
            self.params.bind(marker)

    def action_map_pick(self) -> None:
        self.params.pick()

    # -- disabled keys are explained, like on the mission screen -----------------------------------
    async def run_named(self, action: str) -> None:
        if action in MAP_ACTIONS:
            await self.run_action(action)
