"""The fleet screen: every robot with presence, type, battery and link history
(sparklines), what it is doing and its last report; the selected robot's
manifest below (modules and versions, properties, skills). The filter finds
robots by capability (see console/state/capability.py for the syntax)."""

from __future__ import annotations

import json

from rich.text import Text
from textual import on, work
from textual.app import ComposeResult
from textual.signal import Signal
from textual.widgets import DataTable, Footer, Input, Static

from backend.core.model import UplinkCommand
from backend.protocol.messages import RobotInfo
from console.bindings import bindings, key_names
from console.operations import OperationService
from console.screens.base import ViewScreen
from console.screens.cancel import ask_and_cancel, toast_say
from console.screens.dialogs import ChoiceScreen
from console.screens.team import add_robot, retire_robot
from console.state import link, team
from console.state.capability import (
    filter_examples,
    fleet_order,
    last_report,
    matches,
    offered_skills,
    robot_type,
    sparkline,
)
from console.state.changes import StateChange, Topic
from console.state.contact import out_of_contact, presence_words
from console.state.model import ConsoleModel
from console.state.nowcast import battery_now, nowcast_words, robot_nowcast

SPARK = 6  # samples shown per sparkline (the model keeps model.HISTORY)


class FleetScreen(ViewScreen):
    SCOPE = "fleet"
    COLUMNS = (
        ("Robot", "robot"),
        ("Presence", "presence"),
        ("Type", "type"),
        ("Battery", "battery"),
        ("Link", "link"),
        ("Doing", "doing"),
        ("Uplink", "uplink"),
        ("Last report", "report"),
    )
    # a batch may change any robot's activity or uplink; the others say whose
    TOPICS = frozenset({Topic.MISSION, Topic.FLEET, Topic.TELEMETRY})
    BINDINGS = [*ViewScreen.BINDINGS, *bindings("fleet")]

    def __init__(
        self, model: ConsoleModel, changes: Signal[StateChange], ops: OperationService
    ) -> None:
        super().__init__(changes)
        self.model = model
        self.ops = ops
        self.shown: list[str] = []

    def compose(self) -> ComposeResult:
        yield self.title_bar
        yield Input(placeholder="filter by capability", id="filter")
        yield _RobotTable(id="robots", cursor_type="row", zebra_stripes=False)
        yield Static("", id="detail", classes="detail")
        keys = key_names(self)
        back, schedule = keys.say("app.back"), keys.say("app.show_mission")
        cancel = keys.say("fleet.cancel")
        add, retire = keys.say("fleet.add"), keys.say("fleet.retire")
        yield Static(
            f"type to filter ({back}: back to the list) · {cancel}: cancel a command · "
            f"{add}: add ✚ · {retire}: retire · {schedule}: schedule",
            classes="hint",
        )
        yield Footer()

    # -- cells -------------------------------------------------------------------------
    def _presence(self, robot: str) -> Text:
        info = self.model.robots.get(robot)
        in_team = self._team_presence(robot)
        if in_team is not None:
            return in_team
        if info is None:
            return Text("? unknown", style=self.colour("presence-unknown"))
        return self._heard_presence(info)

    def _team_presence(self, robot: str) -> Text | None:
        """A robot asking to join, or retired (None: neither)."""
        if robot in team.joining(self.model):
            return Text(team.joining_words(self.model, robot), style="bold reverse")
        if team.retired(self.model, robot):
            return Text(f"⊘ retired: {team.retired(self.model, robot)}", style="dim")
        return None

    def _heard_presence(self, info: RobotInfo) -> Text:
        """In or out of contact, online, or offline since when."""
        words = presence_words(info, self.model.clock)  # never "online" while it is closed
        if words:
            away = out_of_contact(info)
            return Text(words, style="italic" if away else self.colour("presence-online"))
        if info.online:
            return Text("● online", style=self.colour("presence-online"))
        since = f" {self.model.clock.stamp_text(info.since)}" if info.since else " (not seen)"
        return Text(f"○ offline{since}", style=f"bold {self.colour('presence-offline')}")

    def _level(self, robot: str, i: int, var: str | None) -> Text:
        """A level's sparkline and last value; a robot's last known ones drawn
        as such (dim, italic), the battery with the now-cast's ('(≈33% now)')."""
        h = [x[i] for x in self.model.history.get(robot, ())]
        if not h:
            return Text("—", style="dim")
        low = var is not None and h[-1] < 0.2
        style = f"bold {self.colour(var)}" if low else ""
        text = Text(f"{sparkline(h, SPARK)} {int(round(h[-1] * 100)):3d}%", style=style)
        if self.model.freshness(robot).stale:
            self._last_known(text, robot, h[-1] if i == 0 else None)
        return text

    def _last_known(self, text: Text, robot: str, battery: float | None) -> None:
        """A stale robot's level, drawn as last known; a battery with its now-cast."""
        text.stylize("dim italic")
        now = battery_now(self.model, robot, battery) if battery is not None else ""
        text.append(f" ({now} now)" if now else "", style="italic")

    def _uplink(self, robot: str) -> Text:
        """'⇡2 1m10s ⇄20s': commands waiting for the robot, its one-way delay."""
        words = [
            link.pending_text(self.model.pending(robot), self.model.clock),
            link.delay_text(link.robot_delay_s(self.model.robots, robot), self.model.clock),
        ]
        text = " ".join(w for w in words if w)
        return Text(text or "—", style="" if text else "dim")

    def _row(self, robot: str) -> list:
        return [
            Text(robot, style="bold"),
            self._presence(robot),
            Text(robot_type(self.model, robot)),
            self._level(robot, 0, "battery-low"),
            self._level(robot, 1, None),
            Text(self.model.activity_text(robot) if self.model.mission else ""),
            self._uplink(robot),
            Text(last_report(self.model, robot)),
        ]

    # -- drawing -------------------------------------------------------------------------
    def redraw(self) -> None:
        if not self.ready:
            return
        t = self.query_one(DataTable)
        keep = (self.selected, t.cursor_row)
        self.shown = self._matching()
        with self.app.batch_update():
            t.clear()
            for r in self.shown:
                t.add_row(*self._row(r), key=r)
            if self.shown:
                t.move_cursor(row=_row_of(self.shown, *keep))
        self._title()
        self._detail()
        # examples from this fleet, so each of them finds something
        self.query_one(
            "#filter", Input
        ).placeholder = f"filter by capability: {filter_examples(self.model)}"

    def update_view(self, change: StateChange) -> None:
        robots = self._rows_to_update(change)
        if robots is None:
            self.redraw()
            return
        t = self.query_one(DataTable)
        for r in robots:
            for (_, key), value in zip(self.COLUMNS, self._row(r), strict=True):
                t.update_cell(r, key, value)
        self._title()
        if self.selected in robots:
            self._detail()

    def _rows_to_update(self, change: StateChange) -> list[str] | None:
        """The rows a change touches; None when the rows themselves change (a
        robot matches the filter or not now, its manifest came, the mission changed)."""
        robot = _only_robot(change)
        if robot is not None and robot in self.shown:
            return [robot]
        if self._matching() != self.shown:
            return None
        return self.shown if robot is None else []

    def _matching(self) -> list[str]:
        """The robots the filter finds, in the fleet's order."""
        return [r for r in fleet_order(self.model) if matches(self.model, r, self.query_text)]

    def _title(self) -> None:
        n, online, away = self._counts()
        shown = f" · {len(self.shown)} match '{self.query_text}'" if self.query_text else ""
        self.set_title(
            ("Fleet", "bold"), f"  {n} robots, {online} online{self._title_notes(away)}{shown}"
        )

    def _counts(self) -> tuple[int, int, int]:
        """Robots, those online (in contact) and those present but out of contact."""
        order = fleet_order(self.model)
        present = [r for r in order if self.model.is_online(r)]
        away = sum(1 for r in present if out_of_contact(self.model.robots.get(r)))
        return len(order), len(present) - away, away

    def _title_notes(self, away: int) -> str:
        """`, 1 out of contact · ✚ lru3 asks to join (a: add)`."""
        notes = f", {away} out of contact" if away else ""
        asking = team.joining(self.model)
        if asking:
            add = key_names(self).say("fleet.add")
            notes += f" · ✚ {', '.join(asking)} asks to join ({add}: add)"
        return notes

    @property
    def selected(self) -> str | None:
        t = self.query_one(DataTable)
        if not self.shown or t.cursor_row is None or t.cursor_row >= len(self.shown):
            return None
        return self.shown[t.cursor_row]

    def _detail(self) -> None:
        """The selected robot in full: presence, activity, manifest, skills."""
        detail = self.query_one("#detail", Static)
        r = self.selected
        if r is None:
            detail.update(
                Text("no robot matches the filter" if self.query_text else "no robots", style="dim")
            )
            return
        out = self._detail_head(r)
        out.append_text(_manifest_text(self.model.robots.get(r)))
        out.append("\nskills: ", style="bold")
        out.append_text(_skills_text(offered_skills(self.model, r), self.query_text))
        detail.update(out)

    def _detail_head(self, r: str) -> Text:
        """Name, type, presence (since when), what it does, its last report."""
        info = self.model.robots.get(r)
        out = Text()
        out.append(r, style="bold")
        out.append(f"  {robot_type(self.model, r)}  ")
        out.append_text(self._presence(r))
        out.append(self._since(info))
        out.append("\ndoing: ", style="bold")
        out.append(self.model.activity_text(r) if self.model.mission else "—")
        out.append(" · last report: ", style="bold")
        out.append(last_report(self.model, r))
        nc = robot_nowcast(self.model, r)  # its report is old: what it probably does now
        if nc is not None:
            out.append(f" · {nowcast_words(nc)}", style="italic")
        out.append("\nlink: ", style="bold")
        out.append(link.link_text(self.model, r, self.model.clock))
        return out

    def _since(self, info: RobotInfo | None) -> str:
        """` since 0:12:00` (` present since` out of contact): an online robot's."""
        if info is None or not info.online or not info.since:
            return ""
        present = "present since" if out_of_contact(info) else "since"
        return f" {present} {self.model.clock.stamp_text(info.since)}"

    # -- cancelling a pending command ----------------------------------------------------
    @work(group="dialog")
    async def action_fleet_cancel(self) -> None:
        """One of the selected robot's pending commands (chosen if several), asking first."""
        say = toast_say(self.app)
        robot = self.selected
        cmds = self.model.pending(robot) if robot else []
        if not cmds:
            say(f"no command waits for {robot or 'a robot'}'s answer", "warning")
            return
        c = cmds[0] if len(cmds) == 1 else await self._which_command(robot, cmds)
        if c is not None:
            await ask_and_cancel(self, self.ops, c, say)

    async def _which_command(
        self, robot: str | None, cmds: list[UplinkCommand]
    ) -> UplinkCommand | None:
        """The command the operator picks of several (None: none)."""
        rows = [(str(x.id), Text(link.command_text(x, self.model.clock))) for x in cmds]
        chosen = await self.app.push_screen_wait(
            ChoiceScreen(f"Cancel which command to {robot}?", rows)
        )
        return next((x for x in cmds if str(x.id) == chosen), None)

    # -- the team: adding a robot that asks to join, retiring one ------------------------
    @work(group="dialog")
    async def action_fleet_add(self) -> None:
        await add_robot(self, self.selected, toast_say(self.app, "Fleet"))

    @work(group="dialog")
    async def action_fleet_retire(self) -> None:
        await retire_robot(self, self.selected, toast_say(self.app, "Fleet"))

    # -- events ---------------------------------------------------------------------------
    @on(DataTable.RowHighlighted)
    def _highlighted(self) -> None:
        self._detail()


def _prop(value: object) -> str:
    """A manifest property as the robot sent it (JSON), as `ctl robots` shows it."""
    return (
        value
        if isinstance(value, str)
        else json.dumps(value, separators=(",", ":"), ensure_ascii=False)
    )


def _manifest_text(info: RobotInfo | None) -> Text:
    """The manifest's modules (with versions) and properties, if the robot registered."""
    man = info.manifest if info else None
    if man is None:
        return Text("\nno manifest yet (never registered): skills from the library", style="dim")
    out = Text()
    out.append("\nmodules: ", style="bold")
    out.append(", ".join(f"{m.name} {m.version}" for m in man.modules) or "—")
    out.append("\nproperties: ", style="bold")
    out.append(", ".join(f"{k}={_prop(v)}" for k, v in man.properties.items()) or "—")
    return out


def _skills_text(skills: dict[str, str], query: str) -> Text:
    """The skills offered (name and version), those the filter's words hit in reverse."""
    words = _filter_words(query)
    out = Text()
    for i, (name, version) in enumerate(sorted(skills.items())):
        if i:
            out.append(", ")
        out.append(name, style="bold reverse" if _hit(name, words) else "")
        if version:
            out.append(f" {version}", style="dim")
    return out


def _filter_words(query: str) -> list[str]:
    """The filter's words, each without its `field:` prefix."""
    return [w.partition(":")[2] if ":" in w else w for w in query.lower().split()]


def _hit(name: str, words: list[str]) -> bool:
    return any(w and w in name.lower() for w in words)


def _only_robot(change: StateChange) -> str | None:
    """The one robot a change is about (None: the mission, or not one robot)."""
    if change.about(Topic.MISSION) or change.robots is None or len(change.robots) != 1:
        return None
    return next(iter(change.robots))


def _row_of(shown: list[str], robot: str | None, row: int) -> int:
    """The selected robot's row once the list changed (a robot added moves in the
    fleet's order), else the same row."""
    return shown.index(robot) if robot in shown else min(row, len(shown) - 1)


class _RobotTable(DataTable):
    """The robots; a longer detail below (a robot's manifest) shrinks it: its
    selected row stays in sight."""

    def on_resize(self) -> None:
        self.call_after_refresh(_cursor_in_sight, self)


def _cursor_in_sight(table: DataTable) -> None:
    """Scroll the table so its cursor row is shown (moving the cursor there would
    post a highlight again, and the detail)."""
    rows = table.scrollable_content_region.height - table.header_height
    row, top = table.cursor_row, round(table.scroll_y)
    if rows > 0 and not top <= row < top + rows:
        table.scroll_to(y=row if row < top else row - rows + 1, animate=False)
