"""The operator console app.

Events come in as messages only (`console.messages.Incoming`): the live
connection (`ClientBridge`) posts the client library's typed events as they
are, tests post the same ones. The app owns one `ConsoleModel`, the
console's only mirror: it hands it each event (`ConsoleModel.take`) and
publishes the one `StateChange` it answers on `changes`, the signal every screen
and the app's own helpers subscribe to (each redraws what it shows of the
topics that changed, in its own callback). Screens never import the app:
they are handed the model, the signal and the `OperationService` (they
submit operations and await their outcome in their own workers) and post
requests (`HelpRequested`, `AlertAcknowledged`). What is not the app's own
is composed: the quit policy, the notification folder, the plan refresher,
the alert announcer, the split escape.
"""

from __future__ import annotations

import asyncio
import gc
import signal
import threading
from collections.abc import Callable
from datetime import datetime
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from textual import events, on
from textual.app import App
from textual.notifications import SeverityLevel
from textual.screen import Screen
from textual.signal import Signal

from backend.client.client import ClientError, LoginFailed
from backend.exit_codes import EXIT_UNREACHABLE
from backend.transport.login import Login
from console.alerting import AlertAnnouncer, QuestionPrompter
from console.bindings import bind, bindings, key_names
from console.bridge import ClientBridge
from console.commands import MissionCommands
from console.config import ConsoleConfig, save_theme
from console.escape import EscapeSplitter
from console.hangup import (
    detach_terminal,
    force_exit,
    handle_signals,
    start_watchdog,
    unhandle_signals,
)
from console.messages import AlertAcknowledged, HelpRequested, Incoming, QuestionRequested
from console.notifier import NotificationFolder
from console.operations import Backend, OperationService, ReadOnlyBackend
from console.plan_modes import PlanRefresher
from console.quitting import QuitPolicy
from console.screens.dialogs import HelpScreen, UnreachableScreen
from console.screens.mission import TCSS as MISSION_TCSS
from console.screens.mission import MissionScreen
from console.screens.question import open_question
from console.state.actions import ACTIONS
from console.state.changes import (
    Connecting,
    ModelEvent,
    StateChange,
    Topic,
    Unreachable,
    change,
)
from console.state.clock import MissionClock
from console.state.eventlog import AlertBook, EventLog
from console.state.files import RecentFiles
from console.state.model import OFFLINE, ConsoleModel
from console.state.text import without_paths
from console.themes.loader import ANSI16_MAP, ANSI16_STATUS, Downgrade16, choose_theme, load_themes
from console.themes.variables import VARIABLE_DEFAULTS
from console.typeahead import TypeAhead

if TYPE_CHECKING:
    from backend.protocol.mapfeed import SimStatus
    from console.screens.map import MapScreen

HERE = Path(__file__).parent


# the part-2 screens (app modes beside the schedule's), each made by a function
# that imports its module: none is needed before the first frame
def _map_screen(app: MissionApp) -> Screen:
    from console.screens.map import MapScreen

    return MapScreen(app.model, app.changes, app.ops)


def _fleet_screen(app: MissionApp) -> Screen:
    from console.screens.fleet import FleetScreen

    return FleetScreen(app.model, app.changes, app.ops)


def _log_screen(app: MissionApp) -> Screen:
    from console.screens.log import EventLogScreen

    return EventLogScreen(app.model.log, app.changes, app.model.clock)


def _alert_screen(app: MissionApp) -> Screen:
    from console.screens.alerts import AlertScreen

    return AlertScreen(app.model.alerts, app.changes, app.model.clock)


def _timeline_screen(app: MissionApp) -> Screen:
    from console.screens.timeline import TimelineScreen

    return TimelineScreen(app.model, app.changes)


def _checks_screen(app: MissionApp) -> Screen:
    from console.screens.checks import ChecksScreen

    return ChecksScreen(app.model, app.changes, app.ops)


PART_2_SCREENS: dict[str, Callable[[MissionApp], Screen]] = {
    "map": _map_screen,
    "fleet": _fleet_screen,
    "log": _log_screen,
    "alerts": _alert_screen,
    "timeline": _timeline_screen,
    "checks": _checks_screen,
}


class MissionApp(App[int]):
    TITLE = "missionctl"
    cursor_blink = True  # tests turn it off for deterministic snapshots
    DEFAULT_MODE = "mission"
    COMMANDS = App.COMMANDS | {MissionCommands}
    BINDINGS = [
        bind("app.quit", "quit", show=True),
        bind("app.command_palette", "command_palette"),
        bind("app.answer", "answer", show=False),
        *bindings("app", show=False),  # shown in the footers of the part-2 screens
    ]
    # the app's look and its widgets' (each screen loads its own: CSS_PATH there;
    # the first screen's is read with the app's: Textual would otherwise parse
    # every stylesheet once more before the first frame, when that screen loads);
    # absolute, so a subclass defined elsewhere (tests) finds them too
    CSS_PATH = [
        HERE / "app.tcss",
        HERE / "widgets" / "bars.tcss",
        HERE / "widgets" / "schedule" / "schedule.tcss",
        HERE / "widgets" / "editor" / "editor.tcss",
        HERE / "widgets" / "map" / "map.tcss",
        MISSION_TCSS,  # last, as when its screen loads it
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
        observer: str = "",
    ) -> None:
        """`observer`: why this console never changes the mission, whatever
        its account ("" when it may): read-only, and nothing is submitted."""
        super().__init__()
        self.config = config or ConsoleConfig()
        self.recent = RecentFiles(self.config.recent_path)
        self.notices = [*notices, *self.config.problems]
        self.model = ConsoleModel(endpoint=connect or "", observer=observer, read_only=observer)
        if observer:
            backend = ReadOnlyBackend(observer)
        # the one notice of what changed: every screen and helper subscribes
        self.changes: Signal[StateChange] = Signal(self, "changes")
        # 16 colours (asked for, or a TERM=xterm terminal: see on_mount)
        self.colour_count = colors
        self.ansi16 = False
        if colors == 16:
            self._use_16_colours()
        self._load_themes(theme or self.config.theme)
        self.bridge = (  # the live connection (none: tests post the events themselves)
            ClientBridge(self._post_event, connect, user=user, client_id=client_id, login=login)
            if connect
            else None
        )
        self.login_refused = ""  # set when the router refused the login: the CLI prints it, exit 3
        self.backend: Backend | None = backend or self.bridge
        # composed: each does one thing for the app
        self.ops = OperationService(
            self.model, lambda: self.backend, self.notify, self.publish, self.whoami
        )
        # quitting asks when robots execute, commands wait or the plan is unsaved
        # (--yes: never); `quitting_stops` says what else ends with the console (the demo)
        self.quitting = QuitPolicy(
            self, self.model, self.quit_now, ask=ask_before_quit, stops=quitting_stops
        )
        self.folder = NotificationFolder(self)
        self.escape = EscapeSplitter(self)
        self.announcer = AlertAnnouncer(self)
        self.plan = PlanRefresher(self.model, self.publish, self._sim_status())
        self.prompter = QuestionPrompter(self)  # a robot's question opens its dialog
        self.mission_screen: MissionScreen | None = None
        self.map_screen: MapScreen | None = None
        # the screens as app modes (F2/1 back to the schedule), each handed the
        # state it shows and the signal that says it changed
        # (the part-2 screens' modules are imported when first shown: the first
        # frame is the schedule's, and it comes sooner without them)
        self.add_mode(self.DEFAULT_MODE, self.get_default_screen)
        for mode in PART_2_SCREENS:
            self.add_mode(mode, partial(self._make_screen, mode))
        if self.config.keymap:
            self.set_keymap(self.config.keymap)
        self.model.keys = key_names(self)  # the rules' sentences name the user's keys
        self._connection_closed = False
        self._hanging_up = False
        self.on_forced_exit: list[Callable[[], object]] = []  # before a forced exit (hang-up)
        self.exit_code = 0
        # keys typed while a dialog opens wait for it (console/typeahead.py)
        self.typeahead = TypeAhead(self, self._key_as_typed)

    def _load_themes(self, wanted: str | None) -> None:
        """Register the themes (before any CSS is parsed), then use the one asked for."""
        themes, problems = load_themes()
        self.notices.extend(problems)
        for t in themes.values():
            self.register_theme(t)
        self.theme, notice = choose_theme(wanted, self.available_themes)
        if notice:
            self.notices.append(notice)

    def _sim_status(self) -> Callable[[], SimStatus | None] | None:
        """Where the plan reads the simulator's status (None without a connection)."""
        bridge = self.bridge
        return (lambda: bridge.sim_status) if bridge is not None else None

    @property
    def clock(self) -> MissionClock:
        """The mission clock (console/state/clock.py); setting it pins its wall clock (tests)."""
        return self.model.clock

    @clock.setter
    def clock(self, wall: Callable[[], datetime]) -> None:
        self.model.clock.wall = wall

    @property
    def event_log(self) -> EventLog:
        return self.model.log

    @property
    def alerts(self) -> AlertBook:
        return self.model.alerts

    @property
    def bells(self) -> int:
        return self.announcer.bells

    # -- events in, one change out --------------------------------------------------------
    def _post_event(self, event: ModelEvent) -> None:
        self.post_message(Incoming(event))

    @on(Incoming)
    def _incoming(self, message: Incoming) -> None:
        event = message.event
        c = self.model.take(event)
        if c.loaded:
            # a big mission is many long-lived objects: keep them out of the cyclic
            # GC's scans, which otherwise stall the UI for tens of milliseconds
            gc.freeze()
        self.publish(c)
        if isinstance(event, Unreachable) and not isinstance(self.screen, UnreachableScreen):
            self.push_screen(
                UnreachableScreen(self.model.endpoint or "?", event.detail),
                self._unreachable_choice,
            )

    def publish(self, c: StateChange) -> None:
        """Tell every subscriber what changed (nothing: nobody)."""
        if c and self._running and self.return_code is None:
            self.changes.publish(c)

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
    def get_default_screen(self) -> Screen:
        self.mission_screen = MissionScreen(self.model, self.changes, self.ops, self.recent)
        self.ops.fallback_say = self.mission_screen.say  # screens without a status line
        return self.mission_screen

    def _make_screen(self, mode: str) -> Screen:
        screen = PART_2_SCREENS[mode](self)
        if mode == "map":
            self.map_screen = cast("MapScreen", screen)
        return screen

    def action_show_mission(self) -> None:
        self.switch_mode(self.DEFAULT_MODE)

    def action_show_map(self) -> None:
        self.switch_mode("map")

    def action_show_fleet(self) -> None:
        self.switch_mode("fleet")

    def action_show_log(self) -> None:
        self.switch_mode("log")

    def action_show_alerts(self) -> None:
        self.switch_mode("alerts")

    def action_show_timeline(self) -> None:
        self.switch_mode("timeline")

    def action_show_checks(self) -> None:
        self.switch_mode("checks")

    # every action this app binds (console/state/actions.py; a review adds its own)
    ACTIONS = ACTIONS

    def action_help(self) -> None:
        if not isinstance(self.screen, HelpScreen):
            self.push_screen(HelpScreen(key_names(self), self.ACTIONS))

    @on(HelpRequested)
    def _help_requested(self) -> None:
        self.action_help()

    def action_answer(self) -> None:
        """A robot's question: the oldest open one (console/screens/question.py)."""
        open_question(self)

    @on(QuestionRequested)
    def _question_requested(self, message: QuestionRequested) -> None:
        open_question(self, message.question_id)

    @on(AlertAcknowledged)
    def _alert_acknowledged(self, message: AlertAcknowledged) -> None:
        self.acknowledge(message.alert_id)

    def acknowledge(self, alert_id: int | None) -> int:
        n = self.model.alerts.acknowledge(alert_id)
        if n:
            self.publish(change(Topic.ALERTS))
        return n

    # -- composed behaviour ----------------------------------------------------------------
    def notify(
        self,
        message: str,
        *,
        title: str = "",
        severity: SeverityLevel = "information",
        timeout: float | None = None,
        markup: bool = True,
    ) -> None:
        """A toast without absolute file paths, folded (console/notifier.py)."""
        message, title = without_paths(str(message)), without_paths(title)
        if threading.get_ident() != self._thread_id:  # from another thread: as Textual does
            super().notify(message, title=title, severity=severity, timeout=timeout, markup=markup)
        else:
            self.folder.notify(
                message, title=title, severity=severity, timeout=timeout, markup=markup
            )

    async def on_event(self, event: events.Event) -> None:
        if not await self.typeahead.take(event):  # held while a dialog opens: typeahead.py
            await self.escape.on_event(event, super().on_event)

    async def _key_as_typed(self, key: events.Key) -> None:
        await self.escape.on_event(key, super().on_event)

    async def action_quit(self) -> None:
        await self.quitting.quit()

    def refresh_plan(self, force: bool = False) -> None:
        self.plan.refresh(force=force)

    def whoami(self) -> dict[str, str]:
        """This console's client id and user, as the event log names them."""
        b = self.bridge
        client = b.client.client_id if b is not None and b.client is not None else "this console"
        return {"client": client, "user": b.user if b is not None else ""}

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
        self.announcer.start(self.changes)
        self.prompter.start(self.changes)
        if self.bridge is not None:
            self.connect_now()
        self.plan.start(self, self.changes)

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
        self._post_event(Connecting(self.bridge.endpoint))
        try:
            await self.bridge.connect()
        except LoginFailed as e:  # retrying cannot help: one line and exit code 3
            self.login_refused = str(e)
            self.exit(EXIT_UNREACHABLE, return_code=EXIT_UNREACHABLE)
        except ClientError as e:
            self._post_event(Unreachable(str(e)))
        except Exception as e:  # never a traceback for a network problem
            self._post_event(Unreachable(f"{type(e).__name__}: {e}"))

    def _unreachable_choice(self, choice: str | None) -> None:
        if choice == "retry":
            self.connect_now()
        else:
            self.model.connection = OFFLINE
            self.exit_code = EXIT_UNREACHABLE
            self.run_worker(self.quit_now(), group="quit")
