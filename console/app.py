"""The operator console app.

State comes in as messages only (`console.messages`): the live connection
(`ClientBridge`) posts them from client callbacks, tests post them directly.
The app owns one `ConsoleModel`, updates it in the message handlers and tells
the screens what changed; it hands each screen the state it shows. Screens
never import the app: they post requests (`OperationRequested`,
`HelpRequested`, `AlertAcknowledged`) that the app handles. Operations run in
workers, so the UI never waits on the network; their refusals name robot,
skill and reason in a notification and on the status line.
"""

from __future__ import annotations

import asyncio
import gc
import signal
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import Any

from textual import events, on
from textual.app import App
from textual.screen import Screen
from textual.signal import Signal

from backend.client.client import ClientError, LoginFailed, OperationRefused
from backend.exit_codes import EXIT_UNREACHABLE
from backend.protocol.messages import ErrorReply
from backend.transport.login import Login
from console.bindings import bind, bindings, key_names
from console.bridge import Backend, ClientBridge
from console.commands import MissionCommands
from console.config import ConsoleConfig, save_theme
from console.escape import SplitEscape
from console.hangup import (
    detach_terminal,
    force_exit,
    handle_signals,
    start_watchdog,
    unhandle_signals,
)
from console.messages import (
    AccountKnown,
    AlertAcknowledged,
    AlertReceived,
    ConnectionChanged,
    EventsApplied,
    FleetChanged,
    HelpRequested,
    MapChanged,
    MessageUnreadable,
    OperationRequested,
    StateLoaded,
    TelemetryChanged,
)
from console.notifier import FoldingNotifications
from console.plan_modes import PlanModes
from console.quitting import QuitQuestion
from console.screens.alerts import AlertScreen
from console.screens.dialogs import HelpScreen, UnreachableScreen
from console.screens.fleet import FleetScreen
from console.screens.log import EventLogScreen
from console.screens.map import MapScreen
from console.screens.mission import MissionScreen
from console.state.clock import MissionClock
from console.state.eventlog import AlertBook, AlertEntry, EventLog, toast_text
from console.state.files import RecentFiles
from console.state.model import CONNECTED, CONNECTING, OFFLINE, UNREACHABLE, ConsoleModel
from console.state.site import Site
from console.themes.loader import ANSI16_MAP, ANSI16_STATUS, Downgrade16, choose_theme, load_themes
from console.themes.variables import VARIABLE_DEFAULTS
from console.typeahead import TypeAhead

HERE = Path(__file__).parent


def refusal_text(reply: ErrorReply, robot: str | None = None, skill: str | None = None) -> str:
    """'[lru1 · lru1-3] cannot edit …': who it is about, then the server's sentence."""
    who = [x for x in (reply.robot or robot, reply.skill or skill) if x]
    head = f"[{' · '.join(who)}] " if who else ""
    return f"{head}{reply.message}"


class MissionApp(SplitEscape, FoldingNotifications, QuitQuestion, PlanModes, App[int]):
    TITLE = "missionctl"
    cursor_blink = True  # tests turn it off for deterministic snapshots
    DEFAULT_MODE = "mission"
    COMMANDS = App.COMMANDS | {MissionCommands}
    BINDINGS = [
        bind("app.quit", "quit", show=True),
        bind("app.command_palette", "command_palette"),
        *bindings("app", show=False),  # shown in the footers of the part-2 screens
    ]
    # the app's look and its widgets' (each screen loads its own: CSS_PATH there);
    # absolute, so a subclass defined elsewhere (tests) finds them too
    CSS_PATH = [
        HERE / "app.tcss",
        HERE / "widgets" / "bars.tcss",
        HERE / "widgets" / "schedule" / "schedule.tcss",
        HERE / "widgets" / "editor" / "editor.tcss",
        HERE / "widgets" / "map" / "map.tcss",
    ]

    def __init__(
        self,
        *,
        connect: str | None = None,
        user: str = "",
        theme: str | None = None,
        config: ConsoleConfig | None = None,
        backend: Backend | None = None,
        notices: list[str] | tuple[str, ...] = (),
        client_id: str | None = None,
        colors: int | None = None,
        login: Login | None = None,
        ask_before_quit: bool = True,
        quitting_stops: str = "",
    ) -> None:
        super().__init__()
        self.config = config or ConsoleConfig()
        # quitting asks when robots execute, commands wait or the plan is unsaved
        # (--yes: never); `quitting_stops` says what else ends with the console (the demo)
        self.ask_before_quit = ask_before_quit
        self.quitting_stops = quitting_stops
        self.recent = RecentFiles(self.config.recent_path)
        self.notices = [*notices, *self.config.problems]
        self.model = ConsoleModel(endpoint=connect or "")
        # 16 colours (asked for, or a TERM=xterm terminal: see on_mount)
        self.colour_count = colors
        self.ansi16 = False
        if colors == 16:
            self._use_16_colours()
        themes, problems = load_themes()
        self.notices.extend(problems)
        for t in themes.values():
            self.register_theme(t)
        self.theme, notice = choose_theme(theme or self.config.theme, self.available_themes)
        if notice:
            self.notices.append(notice)
        # what the fleet, event-log and alert screens show; bounded (see eventlog.py)
        self.event_log = EventLog()
        self.alerts = AlertBook()
        self.awareness_signal: Signal[tuple[str, str | None]] = Signal(self, "awareness")
        self.bells = 0  # how often the bell rang (tests)
        self.add_mode(self.DEFAULT_MODE, self.get_default_screen)
        # part-2 screens as app modes (F2/1 back to the schedule; F3/2 is the map's),
        # each handed the state it shows and the signal that says it changed
        changes = self.awareness_signal
        self.add_mode("fleet", lambda: FleetScreen(self.model, changes))
        self.add_mode("log", lambda: EventLogScreen(self.event_log, changes, self.model.clock))
        self.add_mode("alerts", lambda: AlertScreen(self.alerts, changes, self.model.clock))
        self.map_screen: MapScreen | None = None
        self.map_feed: tuple[object, object] | None = None  # the latest (mirror, update)
        self.add_mode("map", self._make_map_screen)
        self.add_plan_modes()  # timeline (F7) and checks (F8): console/plan_modes.py
        if self.config.keymap:
            self.set_keymap(self.config.keymap)
        self.model.keys = key_names(self)  # the rules' sentences name the user's keys
        self.bridge = (
            ClientBridge(self, connect, user=user, client_id=client_id, login=login)
            if connect
            else None
        )
        self.login_refused = ""  # set when the router refused the login: the CLI prints it, exit 3
        self.backend: Backend | None = backend or self.bridge
        self.mission_screen: MissionScreen | None = None
        self._connection_closed = False
        self._hanging_up = False
        self.on_forced_exit: list[Callable[[], object]] = []  # before a forced exit (hang-up)
        self.exit_code = 0
        self.typeahead = TypeAhead(self, self._key_as_typed)

    async def on_event(self, event: events.Event) -> None:
        if not await self.typeahead.take(event):  # keys typed while a dialog opens wait for it
            await super().on_event(event)

    async def _key_as_typed(self, key: events.Key) -> None:
        await super().on_event(key)

    @property
    def clock(self) -> MissionClock:
        """The mission clock (console/state/clock.py); setting it pins its wall clock (tests)."""
        return self.model.clock

    @clock.setter
    def clock(self, wall: Callable[[], datetime]) -> None:
        self.model.clock.wall = wall

    # -- theme and screens --------------------------------------------------------------
    def get_theme_variable_defaults(self) -> dict[str, str]:
        return dict(VARIABLE_DEFAULTS)

    def get_css_variables(self) -> dict[str, str]:
        variables = super().get_css_variables()
        if getattr(self, "ansi16", False):  # (called by App.__init__ before it is set)
            variables.update(ANSI16_STATUS)
            variables.update(ANSI16_MAP)
            self.theme_variables = variables
        return variables

    def _use_16_colours(self) -> None:
        """Statuses get one ANSI colour each (ANSI16_STATUS), the map's ground
        colours that stay apart (ANSI16_MAP); everything is
        drawn with the 16 standard colours, as the terminal would."""
        self.ansi16 = True
        self._filters.append(Downgrade16())

    def _theme_picked(self, theme: Any) -> None:
        """Remember a theme picked in the palette in the user's config file."""
        path = self.config.path
        if path is None or theme.name == self.config.theme:
            return
        problem = save_theme(path, theme.name)
        if problem:
            self.notify(problem, title="Settings", severity="warning")
        else:
            self.config.theme = theme.name

    # -- screens (app modes) -------------------------------------------------------------
    def action_show_mission(self) -> None:
        self.switch_mode(self.DEFAULT_MODE)

    def _make_map_screen(self) -> Screen:
        self.map_screen = MapScreen(self.model)
        if self.map_feed is not None:
            self.map_screen.map_changed(*self.map_feed)
        return self.map_screen

    def action_show_map(self) -> None:
        self.switch_mode("map")

    def _map_live(self) -> bool:
        return (
            self.map_screen is not None
            and self.map_screen.is_mounted
            and self._running
            and self.return_code is None
        )

    def action_show_fleet(self) -> None:
        self.switch_mode("fleet")

    def action_show_log(self) -> None:
        self.switch_mode("log")

    def action_show_alerts(self) -> None:
        self.switch_mode("alerts")

    def get_default_screen(self) -> Screen:
        self.mission_screen = MissionScreen(self.model, self.alerts, self.recent)
        return self.mission_screen

    def action_help(self) -> None:
        if not isinstance(self.screen, HelpScreen):
            self.push_screen(HelpScreen(key_names(self)))

    @on(HelpRequested)
    def _help_requested(self) -> None:
        self.action_help()

    # -- start / stop ---------------------------------------------------------------------
    def on_mount(self) -> None:
        if not self.is_headless:
            handle_signals(asyncio.get_running_loop(), self._hang_up)
        for n in self.notices:
            self.notify(n, title="Settings", severity="warning", timeout=10)
        self.theme_changed_signal.subscribe(self, self._theme_picked)
        if (
            self.colour_count is None
            and not self.is_headless
            and self.console.color_system == "standard"
        ):
            self._use_16_colours()
            self.refresh_css()
        if self.bridge is not None:
            self.connect_now()
        self.start_plan()

    async def on_unmount(self) -> None:
        """However the app ends (quit, hang-up, a test's teardown): close the
        Zenoh session — a process with an open session never exits."""
        await self.close_connection()
        if not self.is_headless:
            unhandle_signals(asyncio.get_running_loop())

    def _hang_up(self, sig: int = signal.SIGTERM) -> None:
        """SIGHUP (the SSH link dropped) or SIGTERM: close the session, exit;
        without the terminal after a hang-up, and with a watchdog that runs the
        `on_forced_exit` hooks and ends the process should the exit hang
        (console/hangup.py says why)."""
        if self._hanging_up:
            return
        self._hanging_up = True
        if sig == signal.SIGHUP:
            detach_terminal()
        start_watchdog(lambda: force_exit(self.on_forced_exit, self.exit_code))
        self.run_worker(self.quit_now(), group="quit")

    async def quit_now(self) -> None:
        await self.close_connection()
        self.exit(self.exit_code, return_code=self.exit_code)

    async def close_connection(self) -> None:
        if self._connection_closed or self.bridge is None:
            return
        self._connection_closed = True
        try:
            await asyncio.wait_for(self.bridge.close(), 5)
        except (TimeoutError, Exception):
            pass

    def connect_now(self) -> None:
        self.run_worker(self._connect(), group="connect", exclusive=True, exit_on_error=False)

    async def _connect(self) -> None:
        assert self.bridge is not None
        self.post_message(ConnectionChanged(CONNECTING, endpoint=self.bridge.endpoint))
        try:
            await self.bridge.connect()
        except LoginFailed as e:  # retrying cannot help: one line and exit code 3
            self.login_refused = str(e)
            self.exit(EXIT_UNREACHABLE, return_code=EXIT_UNREACHABLE)
        except ClientError as e:
            self.post_message(ConnectionChanged(UNREACHABLE, str(e), endpoint=self.bridge.endpoint))
        except Exception as e:  # never a traceback for a network problem
            self.post_message(
                ConnectionChanged(
                    UNREACHABLE, f"{type(e).__name__}: {e}", endpoint=self.bridge.endpoint
                )
            )

    # -- state comes in as messages --------------------------------------------------------------
    def _screen_live(self) -> bool:
        return (
            self.mission_screen is not None
            and self.mission_screen.is_mounted
            and self._running
            and self.return_code is None
        )

    async def on_state_loaded(self, message: StateLoaded) -> None:
        previous = self.model.mission  # None on the first load; else a resync after a reconnect
        before = (
            {s.id: s.status.value for t in previous.tasks.values() for s in t}
            if previous is not None
            else {}
        )
        self.model.load(message.mission, message.library, message.robots, message.server_id)
        # a big mission is many long-lived objects: keep them out of the cyclic
        # GC's scans, which otherwise stall the UI for tens of milliseconds
        gc.freeze()
        # what happened while the console was away alerts too
        now = self.clock() if previous is not None else None
        missed = self.alerts.seed_fleet(self.model.robots, now)
        if now is not None:
            missed += self.alerts.missed_failures(before, self.model.mission, now)
        for a in missed:
            if a.kind == "failure":  # no report of it reached this console: log it here
                self.event_log.add(
                    "failure", a.message, a.at, robots=[a.robot] if a.robot else [], skill=a.skill
                )
            self.raise_alert(a)
        if self._screen_live():
            await self.mission_screen.model_changed(None)
        if self._map_live():
            self.map_screen.model_changed()
        self.awareness_signal.publish(("fleet", None))

    async def on_events_applied(self, message: EventsApplied) -> None:
        robots = self.model.apply(message.batch, message.mission)
        if self._screen_live() and robots != set():
            await self.mission_screen.model_changed(robots)
            self.mission_screen.batch_seen(message.batch)  # the cursor may follow an undo
        if self._map_live():  # marker events change no robot's column but the map
            self.map_screen.model_changed()
        entries = self.event_log.add_batch(message.batch, self.model, self.clock())
        for a in self.alerts.from_batch(entries):
            self.raise_alert(a)
        self.awareness_signal.publish(("log", None))
        self.awareness_signal.publish(("fleet", None))

    def on_fleet_changed(self, message: FleetChanged) -> None:
        self.model.set_robot(message.info)
        if self._screen_live():
            self.mission_screen.robot_changed(message.info.name)
        if self._map_live():
            self.map_screen.fleet_changed()
        a = self.alerts.from_fleet(message.info, self.clock())
        if a is not None:
            self.raise_alert(a)
        self.awareness_signal.publish(("fleet", message.info.name))

    def on_telemetry_changed(self, message: TelemetryChanged) -> None:
        self.model.set_telemetry(message.telemetry)
        if self._screen_live():
            self.mission_screen.telemetry_changed(message.telemetry.robot)
        if self._map_live():
            self.map_screen.telemetry_changed(message.telemetry.robot)
        for a in self.alerts.from_telemetry(message.telemetry, self.clock()):
            self.raise_alert(a)
        self.awareness_signal.publish(("fleet", message.telemetry.robot))

    def on_map_changed(self, message: MapChanged) -> None:
        self.map_feed = (message.mirror, message.update)
        objects = getattr(message.mirror, "objects", None)
        if objects is not None:  # a simulator: its score on the top bar, its time the clock's
            self.model.site = Site(objects.score)
            first = not self.model.clock.simulated  # times shown so far were wall times
            self.model.clock.heard(message.mirror.sim_time, message.mirror.speed)
            if self._screen_live():
                self.mission_screen.update_top()
                if first:
                    self.mission_screen.schedule.refresh()
        if self._map_live():
            self.map_screen.map_changed(message.mirror, message.update)

    async def on_connection_changed(self, message: ConnectionChanged) -> None:
        m = self.model
        previous = m.connection
        m.connection = message.status
        m.connection_detail = message.detail
        if message.endpoint is not None:
            m.endpoint = message.endpoint
        if self._screen_live():
            await self.mission_screen.connection_changed()
            if message.status == "reconnecting":
                self.mission_screen.say(
                    f"connection to {m.endpoint} lost — reconnecting "
                    "(the server may be restarting)…",
                    "warning",
                )
            elif message.status == CONNECTED and previous == "reconnecting":
                revision = m.mission.revision if m.mission else "?"
                self.mission_screen.say(
                    f"reconnected to {m.endpoint}: state resynchronized at revision {revision}",
                    "ok",
                )
                self.notify("reconnected; state resynchronized", title="Server", timeout=3)
        if self._map_live():
            self.map_screen.connection_changed()
        if message.status == UNREACHABLE and not isinstance(self.screen, UnreachableScreen):
            self.push_screen(
                UnreachableScreen(m.endpoint or "?", message.detail), self._unreachable_choice
            )

    async def on_account_known(self, message: AccountKnown) -> None:
        self.model.read_only = message.read_only
        if self._screen_live():
            await self.mission_screen.connection_changed()  # top bar, actions, editor

    def _unreachable_choice(self, choice: str | None) -> None:
        if choice == "retry":
            self.connect_now()
        else:
            self.model.connection = OFFLINE
            self.exit_code = EXIT_UNREACHABLE
            self.run_worker(self.quit_now(), group="quit")

    def on_alert_received(self, message: AlertReceived) -> None:
        """The server's alert; one the console raised itself already is merged."""
        a = self.alerts.from_server(message.alert)
        if a is not None:
            self.raise_alert(a)
        else:
            self.awareness_signal.publish(("alerts", None))

    def on_message_unreadable(self, message: MessageUnreadable) -> None:
        """Someone on the network speaks another protocol: say so once (an
        integrator bringing up a robot sees why its telemetry never shows)."""
        a = self.alerts.add("malformed", message.text, self.clock(), robot=message.robot)
        if a is not None:
            self.raise_alert(a)

    # -- alerts -------------------------------------------------------------------------------
    def raise_alert(self, a: AlertEntry, *, notify: bool = True) -> None:
        """A new alert: log it, ring the bell, notify; the badge and list update."""
        if a.kind not in ("failure", "refusal"):  # those are log lines already
            self.event_log.add(
                "alert",
                a.message,
                a.at,
                robots=[a.robot] if a.robot else [],
                skill=a.skill,
                client=a.source,
            )
        if a.level != "info":
            self.ring()
        if notify:
            severity = {"error": "error", "warning": "warning"}.get(a.level, "information")
            title, text = toast_text(self.alerts, a)  # robots going offline together: one
            self.notify(
                text, title=title, severity=severity, timeout=8 if a.level == "error" else 5
            )
        if self._screen_live() and a.level == "error":
            self.mission_screen.say(f"✗ {a.message}", "error")
        self.alerts_changed()

    def ring(self) -> None:
        self.bells += 1
        self.bell()

    def acknowledge(self, alert_id: int | None) -> int:
        n = self.alerts.acknowledge(alert_id)
        if n:
            self.alerts_changed()
        return n

    @on(AlertAcknowledged)
    def _alert_acknowledged(self, message: AlertAcknowledged) -> None:
        self.acknowledge(message.alert_id)

    def alerts_changed(self) -> None:
        if self._screen_live():
            self.mission_screen.update_top()
        self.awareness_signal.publish(("alerts", None))
        self.awareness_signal.publish(("log", None))

    # -- operations ---------------------------------------------------------------------
    @on(OperationRequested)
    def submit(self, request: OperationRequested) -> None:
        """Run a screen's operation in a worker: the UI never waits on the network."""
        if self.backend is None:
            self.notify("not connected to a mission server", severity="error")
            return
        self.run_worker(self._submit(request), group="ops", exit_on_error=False)

    def whoami(self) -> dict[str, str]:
        """This console's client id and user, as the event log names them."""
        b = self.bridge
        client = b.client.client_id if b is not None and b.client is not None else "this console"
        return {"client": client, "user": b.user if b is not None else ""}

    def _refused(self, text: str, robot: str | None, skill: str | None) -> None:
        """The console's own refusal: logged, an alert (already notified)."""
        at = self.clock()
        self.event_log.add(
            "refusal", text, at, robots=[robot] if robot else [], skill=skill, **self.whoami()
        )
        a = self.alerts.add("refusal", text, at, robot=robot, skill=skill)
        if a is not None:
            self.raise_alert(a, notify=False)
        else:
            self.alerts_changed()

    async def _submit(self, r: OperationRequested) -> None:
        say = r.say
        if say is None and self.mission_screen is not None:
            say = self.mission_screen.say  # or another screen's status line (the map's)
        say = say or (lambda *a: None)
        say(f"… {r.what}")
        assert self.backend is not None
        try:
            reply = await self.backend.submit(r.op, expected_revision=r.expected_revision)
        except OperationRefused as e:
            self._operation_refused(r, say, e.reply)
            return
        except ClientError as e:
            self._operation_failed(r, say, e)
            return
        if r.on_ok is not None:
            r.on_ok(reply)
        else:
            say(f"✓ {r.what}", "ok")
        for note in reply.notes:
            self.notify(note, title=r.what, severity="warning", timeout=8)

    def _operation_refused(self, r: OperationRequested, say: Any, reply: ErrorReply) -> None:
        text = refusal_text(reply, r.robot, r.skill)
        say(f"✗ {r.what} refused: {text}", "error")
        self.notify(text, title=f"Refused: {r.what}", severity="error", timeout=8)
        self._refused(f"{r.what} refused: {text}", reply.robot or r.robot, reply.skill or r.skill)
        if r.on_refused is not None:
            r.on_refused(reply)

    def _operation_failed(self, r: OperationRequested, say: Any, e: ClientError) -> None:
        say(f"✗ {r.what}: {e}", "error")
        self.notify(str(e), title=f"Failed: {r.what}", severity="error", timeout=8)
        robots = [r.robot] if r.robot else []
        at = self.clock()
        self.event_log.add(
            "failure", f"{r.what}: {e}", at, robots=robots, skill=r.skill, **self.whoami()
        )
        self.awareness_signal.publish(("log", None))
