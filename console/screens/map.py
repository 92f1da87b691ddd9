"""The map screen (app mode "map"): the site, robots, markers and goals.

Layout: top bar / map | legend / info line (cursor, selection, feed) /
status line / footer. Marker edits and parameter picks go through the same
operations as everywhere (backend.core.ops via `app.submit`); the "selected
skill" is the schedule's cursor on the mission screen.
"""

from __future__ import annotations

import math
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

from backend.core.model import (
    Status,
)
from backend.core.ops import EditSkill, MarkerAdd, MarkerDelete, MarkerMove, MarkerRename
from console.bindings import bind, bindings, key_names
from console.messages import HelpRequested
from console.operations import OperationService
from console.screens.dialogs import ChoiceScreen, ConfirmScreen, MarkerPrompt
from console.state.actions import ACTIONS
from console.state.changes import StateChange, Topic
from console.state.contact import CONTACT_GLYPH
from console.state.keys import KeyNames
from console.state.markers import (
    bind_choices,
    followers,
    free_name,
    marker_point,
    marker_use,
    moved_value,
    new_marker,
    picked_value,
    relabel,
)
from console.state.model import CONNECTED, ConsoleModel
from console.state.nowcast import NOWCAST_GLYPH
from console.state.site import here_text
from console.state.text import GLYPHS, STATUS_CSS, STATUS_WORDS, fmt_value
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


def legend_text(colours: dict[str, str] | None = None, keys: KeyNames | None = None) -> Text:
    """The legend; `colours` (theme variables) colour its glyphs like the map."""
    c = colours or {}
    keys = keys or KeyNames()

    def fg(var: str) -> str:
        return f"bold {c[var]}" if var in c else "bold"

    t = Text()

    def row(glyph: str, style: str, what: str) -> None:
        t.append(f" {glyph} ", style=style)
        t.append(f"{what}\n")

    t.append("Legend\n", style="bold")
    row(ROBOT_ARROWS[0], "bold", "robot, heading")
    # the one heading convention (the editor, ctl and the info line use it too)
    t.append("   heading: 0° east,\n   counter-clockwise\n", style="dim")
    for st in (
        Status.RUNNING,
        Status.PAUSED,
        Status.SYNCHWAITING,
        Status.FAILURE,
        Status.IDLE_SYNCHRONIZED,
        Status.IDLE,
    ):
        row(GLYPHS[st], fg(f"status-{STATUS_CSS[st]}"), f"  {STATUS_WORDS[st]}")
    row("✕", fg("presence-offline"), "  offline")
    row(CONTACT_GLYPH, fg("presence-unknown"), "  out of contact")
    row(NOWCAST_ARROWS[0], fg("presence-unknown"), f"{NOWCAST_GLYPH} probably now")
    row(NO_LINK_GLYPH, fg("presence-offline"), "  out of comms range")
    row(FOLLOW_GLYPH, "bold", f"  followed ({keys.say('map.follow')})")
    row(POSE_ARROWS[0], "bold", "pose marker")
    row(POSITION_GLYPH, "bold", "position marker")
    row(AREA_GLYPH, "bold", "area marker")
    row("●", fg("map-marker-active"), "  used on a robot")
    row("○", fg("map-marker-bound"), "  used by idle skill")
    row(GOAL_GLYPH, fg("map-goal"), "goal of a skill")
    row(LANDER_GLYPH, fg("map-lander"), "lander")
    row(BOX_GLYPH, fg("map-box"), "payload box")
    row(RSS_GLYPH, fg("map-rss"), "sampling region")
    row(STONE_GLYPH, fg("map-stone"), "stone found")
    row("·", f"on {c['map-unknown']}" if "map-unknown" in c else "", "unexplored")
    row("~", f"on {c['map-sand']}" if "map-sand" in c else "", "sand (slow)")
    row("▴", f"on {c['map-rock']}" if "map-rock" in c else "", "rock (impassable)")
    row(" ", f"on {c['map-link']}" if "map-link" in c else "reverse", "in comms range")
    row(
        POSE_ARROWS[0],
        f"bold {c['map-cursor']}" if "map-cursor" in c else "bold",
        "cursor (heading)",
    )
    return t


def param_rows(spec: Any, s: Any, names: list[str]) -> list[tuple[str, Text]]:
    """Rows for choosing among a skill's parameters: name, type and what it
    holds now (@MARKER when bound to one), in aligned columns."""
    wn = max(len(n) for n in names)
    wt = max(len(spec.params[n].type) for n in names)
    rows = []
    for n in names:
        ps = spec.params[n]
        if n in s.bindings:
            now = Text(f"@{s.bindings[n]}")
        elif s.params.get(n) is not None:
            now = Text(fmt_value(ps, s.params[n]))
        else:
            now = Text("not set", style="dim")
        rows.append(
            (n, Text.assemble((n.ljust(wn), "bold"), "  ", (ps.type.ljust(wt), "dim"), "  ", now))
        )
    return rows


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


def info_text(model: ConsoleModel, v: MapView, feed_state: str) -> Text:
    """The info lines: the feed (when not live), the cursor and scale, who is
    followed, the selected marker and the schedule's selected skill; then what
    is under the cursor (console/state/site.py)."""
    t = Text()
    if feed_state == "none" or v.mirror is None or not v.mirror.ready:
        why = model.map_note or NO_FEED
        t.append(why if feed_state == "none" else "waiting for the map feed…", style="bold")
        t.append("  ")
    x, y = v.cursor
    t.append(f"cursor ({x:.1f}, {y:.1f}) heading {math.degrees(v.heading):.0f}°")
    t.append(f"  {v.vp.mpp:.2g} m/px", style="dim")
    if v.follow:
        t.append(f"  following {v.follow}", style="bold")
    if v.selected_marker:
        use = marker_use(model).get(v.selected_marker, "unused")
        t.append(f"  marker {v.selected_marker} ({use})")
    found = model.find(v.selected_skill)
    if found is not None:
        s = found[2]
        t.append(f"  skill {s.id} {s.skill} ({STATUS_WORDS[s.status]})", style="dim")
    here = here_text(v.mirror, model.mission, model.telemetry, x, y, tol=max(1.0, v.vp.mpp))
    t.append(f"\nhere: {here}")
    return t


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
        for robot in c.robots or () if c.about(Topic.TELEMETRY) else ():
            self.view.robot_moved(robot)
            if self.view.follow == robot:
                self.update_info()
        if c.about(Topic.FLEET):
            self.view.overlays_changed()
        if c.about(Topic.CONNECTION):
            self.update_top()

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

    def _connected(self) -> bool:
        if self.model.connection != CONNECTED:
            self.say(
                f"not connected to the mission server ({self.model.connection}): "
                "markers cannot be changed now",
                "warning",
            )
            return False
        return True

    def _marker(self) -> Any:
        name = self.view.selected_marker
        m = self.model.mission
        if name is None or m is None or name not in m.markers:
            self.say(
                "select a marker first: n selects the next one (the cursor jumps to it)", "warning"
            )
            return None
        return m.markers[name]

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
        robots = [
            r
            for r in self.model.robot_order()
            if self.model.robot_kind(r) != "static" and r in self.model.telemetry
        ]
        if not robots:
            self.say("no robot position known yet (no telemetry): nothing to follow", "warning")
            return
        # the next robot; after the last one: nobody
        cur = self.view.follow
        i = robots.index(cur) + 1 if cur in robots else 0
        nxt = robots[i] if i < len(robots) else None
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
        self.say(f"marker {name} ({mk.kind}){': ' + mk.description if mk.description else ''}")
        self.update_info()

    # -- actions: markers ------------------------------------------------------------------

    @work(group="dialog")
    async def action_map_add_marker(self) -> None:
        if not self._connected():
            return
        answer = await self.app.push_screen_wait(
            MarkerPrompt("New marker at the cursor — name:", free_name(self.model.mission))
        )
        if not answer:
            return
        name, kind = answer
        x, y = (round(c, 1) for c in self.view.cursor)
        marker = new_marker(kind, x, y, self.view.heading, self.view.vp.mpp)

        def ok(reply: Any) -> None:
            self.view.selected_marker = name
            self.say(f"added {kind} marker {name} at ({x:g}, {y:g})", "ok")

        self.submit(MarkerAdd(name=name, marker=marker), f"add marker {name}", on_ok=ok)

    def action_map_move_marker(self) -> None:
        mk = self._marker()
        if mk is None or not self._connected():
            return
        name = self.view.selected_marker
        following = followers(self.model.mission, name)
        x, y = (round(c, 1) for c in self.view.cursor)
        value = moved_value(mk, x, y, self.view.heading)

        def ok(reply: Any) -> None:
            x, y = self.view.cursor
            text = f"moved {name} to ({x:.1f}, {y:.1f})"
            if following:
                text += f"; {', '.join(following)} follow{'s' if len(following) == 1 else ''}"
            stale = reply.value.get("stale", [])
            if stale:
                text += (
                    f"; {', '.join(stale)} still use{'s' if len(stale) == 1 else ''} "
                    "the old value — unsynchronize to update"
                )
            self.say(text, "warning" if stale else "ok")

        self.submit(MarkerMove(name=name, value=value), f"move marker {name}", on_ok=ok)

    @work(group="dialog")
    async def action_map_rename_marker(self) -> None:
        if self._marker() is None or not self._connected():
            return
        old = self.view.selected_marker
        answer = await self.app.push_screen_wait(
            MarkerPrompt(f"Rename marker {old} to:", old, kinds=False)
        )
        if not answer or answer[0] == old:
            return
        new = answer[0]

        def ok(reply: Any) -> None:
            self.view.selected_marker = new
            self.say(f"renamed {old} to {new}", "ok")

        self.submit(MarkerRename(name=old, new_name=new), f"rename marker {old}", on_ok=ok)

    @work(group="dialog")
    async def action_map_delete_marker(self) -> None:
        if self._marker() is None or not self._connected():
            return
        name = self.view.selected_marker
        if not await self.app.push_screen_wait(
            ConfirmScreen(
                f"Delete marker {name}? Idle skills bound to it keep its value.", yes="Delete"
            )
        ):
            self.say("delete cancelled")
            return

        def ok(reply: Any) -> None:
            self.view.selected_marker = None
            self.say(f"deleted marker {name}", "ok")

        self.submit(MarkerDelete(name=name), f"delete marker {name}", on_ok=ok)

    # -- actions: parameters of the selected skill -------------------------------------------------
    def _skill(self) -> Any:
        self.sync_selection()
        found = self.model.find(self.view.selected_skill)
        if found is None:
            back, here = (key_names(self).say(a) for a in ("app.show_mission", "app.show_map"))
            why = f"select a skill on the schedule first ({back}), then come back ({here})"
            self.say(why, "warning")
            return None
        why = self.model.read_only_reason(found[2].id)
        if why:
            self.say(f"{found[2].id}: {why}", "warning")
            return None
        spec = self.model.library.skills.get(found[2].skill) if self.model.library else None
        if spec is None:
            self.say(f"{found[2].skill} is not in the skill library", "error")
            return None
        return found[0], found[2], spec

    def _choose(
        self,
        question: str,
        spec: Any,
        s: Any,
        names: list[str],
        then: Any,
        *,
        cancelled: str,
        highlighted: int = 0,
    ) -> None:
        """`then(name)` at once when one parameter fits; when several do, the
        operator picks one first (escape: nothing is sent)."""
        if len(names) == 1:
            then(names[0])
            return

        def chosen(pname: str | None) -> None:
            if pname is None:
                self.say(cancelled)
                return
            why = self.model.read_only_reason(s.id)  # it may have changed while the dialog was open
            if why:
                self.say(f"{s.id}: {why}", "warning")
                return
            then(pname)

        self.app.push_screen(
            ChoiceScreen(question, param_rows(spec, s, names), highlighted), chosen
        )

    def action_map_bind(self) -> None:
        mk = self._marker()
        got = self._skill() if mk is not None else None
        if got is None:
            return
        robot, s, spec = got
        name = self.view.selected_marker
        # a parameter the marker can give a value is bound to it; a marker-typed one takes its name
        fits, names = bind_choices(spec, mk)
        if not fits and not names:
            kinds = ", ".join(f"{p} ({ps.type})" for p, ps in spec.params.items()) or "none"
            self.say(
                f"{s.id} ({s.skill}) has no parameter for a {mk.kind} marker; "
                f"its parameters: {kinds}",
                "warning",
            )
            return

        def bind(pname: str) -> None:
            # a label naming the marker bound before ("drive to POI-A") names the new one
            before = s.bindings.get(pname) or (s.params.get(pname) if pname in names else None)
            label = relabel(s.label, before if isinstance(before, str) else None, name)
            op = (
                EditSkill(id=s.id, bindings={pname: name}, label=label)
                if pname in fits
                else EditSkill(id=s.id, params={pname: name}, label=label)
            )
            also = f"; label now '{label}'" if label is not None else ""
            self.submit(
                op,
                f"bind {s.id}.{pname} to {name}",
                robot=robot,
                skill=s.id,
                on_ok=lambda r: self.say(f"{s.id}: {pname} bound to marker {name}{also}", "ok"),
            )

        def holds(p: str) -> bool:
            return s.bindings.get(p) == name or (p in names and s.params.get(p) == name)

        candidates = fits + names
        first = next((i for i, p in enumerate(candidates) if not holds(p)), 0)  # the likely choice
        self._choose(
            f"Bind {name} to which parameter of {s.id}?",
            spec,
            s,
            candidates,
            bind,
            highlighted=first,
            cancelled=f"bind cancelled: {s.id} unchanged",
        )

    def action_map_pick(self) -> None:
        got = self._skill()
        if got is None:
            return
        robot, s, spec = got
        params = [p for p, ps in spec.params.items() if ps.type in ("pose", "position")]
        if not params:
            self.say(f"{s.id} ({s.skill}) has no pose or position parameter", "warning")
            return
        x, y = (round(c, 1) for c in self.view.cursor)

        def pick(pname: str) -> None:
            ptype = spec.params[pname].type
            value = picked_value(ptype, x, y, self.view.heading)
            where = f"({x:g}, {y:g})" + (
                f" heading {math.degrees(self.view.heading):.0f}°" if ptype == "pose" else ""
            )
            unbound = " (its marker binding is replaced)" if pname in s.bindings else ""
            self.submit(
                EditSkill(id=s.id, params={pname: value}),
                f"set {s.id}.{pname}",
                robot=robot,
                skill=s.id,
                on_ok=lambda r: self.say(f"{s.id}: {pname} = {where}{unbound}", "ok"),
            )

        self._choose(
            f"Set which parameter of {s.id} to the cursor ({x:g}, {y:g})?",
            spec,
            s,
            params,
            pick,
            cancelled=f"pick cancelled: {s.id} unchanged",
        )

    # -- disabled keys are explained, like on the mission screen -----------------------------------
    async def run_named(self, action: str) -> None:
        if action in MAP_ACTIONS:
            await self.run_action(action)
