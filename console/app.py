"""The operator console app.

State comes in as messages only (`console.messages`): the live connection
(`ClientBridge`) posts them from client callbacks, tests post them directly.
The app owns one `ConsoleModel`, updates it in the message handlers and tells
the mission screen what changed. Operations run in workers, so the UI never
waits on the network; their refusals name robot, skill and reason in a
notification and on the status line.
"""

from __future__ import annotations

import asyncio
import gc
import signal
from typing import Any

from textual.app import App
from textual.binding import Binding
from textual.screen import Screen

from backend.client import ClientError, LoginFailed, OperationRefused
from backend.login import Login
from backend.protocol import ErrorReply

from .actions import ACTIONS
from .bridge import Backend, ClientBridge
from .commands import MissionCommands
from .config import ConsoleConfig
from .dialogs import HelpScreen, UnreachableScreen
from .messages import (
    AccountKnown,
    AlertReceived,
    ConnectionChanged,
    EventsApplied,
    FleetChanged,
    StateLoaded,
    TelemetryChanged,
)
from .model import CONNECTED, CONNECTING, OFFLINE, UNREACHABLE, ConsoleModel
from .screens import MissionScreen
from .theme import DEFAULT_THEME, MISSIONCTL_DARK, STATUS_DEFAULTS

EXIT_UNREACHABLE = 3


def refusal_text(reply: ErrorReply, robot: str | None = None, skill: str | None = None) -> str:
    """'[lru1 · lru1-3] cannot edit …': who it is about, then the server's sentence."""
    who = [x for x in (reply.robot or robot, reply.skill or skill) if x]
    head = f"[{' · '.join(who)}] " if who else ""
    return f"{head}{reply.message}"


class MissionApp(App[int]):
    TITLE = "missionctl"
    cursor_blink = True  # tests turn it off for deterministic snapshots
    DEFAULT_MODE = "mission"
    COMMANDS = App.COMMANDS | {MissionCommands}
    BINDINGS = [
        Binding("ctrl+q", "quit", "Quit", priority=True, id="app.quit"),
    ]
    CSS = """
    Screen { background: $background; }
    Toast { max-width: 70; }
    """

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
        login: Login | None = None,
    ) -> None:
        super().__init__()
        self.config = config or ConsoleConfig()
        self.notices = [*notices, *self.config.problems]
        self.model = ConsoleModel(endpoint=connect or "")
        self.register_theme(MISSIONCTL_DARK)
        wanted = theme or self.config.theme or DEFAULT_THEME
        if wanted not in self.available_themes:
            self.notices.append(f"unknown theme '{wanted}' (themes: {', '.join(sorted(self.available_themes))}); using {DEFAULT_THEME}")
            wanted = DEFAULT_THEME
        self.theme = wanted
        if self.config.keymap:
            self.set_keymap(self.config.keymap)
        self.bridge = ClientBridge(self, connect, user=user, client_id=client_id, login=login) if connect else None
        self.login_refused = ""  # set when the router refused the login: the CLI prints it, exit 3
        self.backend: Backend | None = backend or self.bridge
        self.mission_screen: MissionScreen | None = None
        self.last_path: str | None = None
        self._connection_closed = False
        self.exit_code = 0

    # -- theme and screens --------------------------------------------------------------
    def get_theme_variable_defaults(self) -> dict[str, str]:
        return dict(STATUS_DEFAULTS)

    def get_default_screen(self) -> Screen:
        self.mission_screen = MissionScreen(self.model)
        return self.mission_screen

    def action_keys(self) -> dict[str, str]:
        """Action name -> its key(s) now (the user's keymap applied)."""
        keymap = getattr(self, "_keymap", {}) or {}
        return {a.name: keymap.get(a.binding_id, a.key) for a in ACTIONS}

    def action_help(self) -> None:
        if not isinstance(self.screen, HelpScreen):
            self.push_screen(HelpScreen(self.action_keys()))

    # -- start / stop ---------------------------------------------------------------------
    def on_mount(self) -> None:
        if not self.is_headless:
            loop = asyncio.get_running_loop()
            for sig in (signal.SIGHUP, signal.SIGTERM):
                try:
                    loop.add_signal_handler(sig, self._hang_up)
                except (NotImplementedError, RuntimeError, ValueError):
                    pass
        for n in self.notices:
            self.notify(n, title="Settings", severity="warning", timeout=10)
        if self.bridge is not None:
            self.connect_now()

    async def on_unmount(self) -> None:
        """However the app ends (quit, hang-up, a test's teardown): close the
        Zenoh session — a process with an open session never exits."""
        await self.close_connection()
        if not self.is_headless:
            loop = asyncio.get_running_loop()
            for sig in (signal.SIGHUP, signal.SIGTERM):
                try:
                    loop.remove_signal_handler(sig)
                except (NotImplementedError, RuntimeError, ValueError):
                    pass

    def _hang_up(self) -> None:
        """SIGHUP (the SSH link dropped) or SIGTERM: close the session, exit."""
        self.run_worker(self.action_quit(), group="quit")

    async def action_quit(self) -> None:
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
            self.post_message(ConnectionChanged(UNREACHABLE, f"{type(e).__name__}: {e}", endpoint=self.bridge.endpoint))

    # -- state comes in as messages --------------------------------------------------------------
    def _screen_live(self) -> bool:
        return self.mission_screen is not None and self.mission_screen.is_mounted and self._running and self.return_code is None

    async def on_state_loaded(self, message: StateLoaded) -> None:
        self.model.load(message.mission, message.library, message.robots, message.server_id)
        # a big mission is many long-lived objects: keep them out of the cyclic
        # GC's scans, which otherwise stall the UI for tens of milliseconds
        gc.freeze()
        if self._screen_live():
            await self.mission_screen.model_changed(None)

    async def on_events_applied(self, message: EventsApplied) -> None:
        robots = self.model.apply(message.batch, message.mission)
        if self._screen_live() and robots != set():
            await self.mission_screen.model_changed(robots)

    def on_fleet_changed(self, message: FleetChanged) -> None:
        self.model.set_robot(message.info)
        if self._screen_live():
            self.mission_screen.robot_changed(message.info.name)

    def on_telemetry_changed(self, message: TelemetryChanged) -> None:
        self.model.set_telemetry(message.telemetry)
        if self._screen_live():
            self.mission_screen.telemetry_changed(message.telemetry.robot)

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
                self.mission_screen.say(f"connection to {m.endpoint} lost — reconnecting (the server may be restarting)…", "warning")
            elif message.status == CONNECTED and previous == "reconnecting":
                self.mission_screen.say(f"reconnected to {m.endpoint}: state resynchronized at revision {m.mission.revision if m.mission else '?'}", "ok")
                self.notify("reconnected; state resynchronized", title="Server", timeout=3)
        if message.status == UNREACHABLE and not isinstance(self.screen, UnreachableScreen):
            self.push_screen(UnreachableScreen(m.endpoint or "?", message.detail), self._unreachable_choice)

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
            self.run_worker(self.action_quit(), group="quit")

    def on_alert_received(self, message: AlertReceived) -> None:
        a = message.alert
        severity = {"error": "error", "warning": "warning"}.get(a.level, "information")
        title = " · ".join(x for x in (a.robot, a.skill) if x) or "Alert"
        self.notify(a.message, title=title, severity=severity, timeout=8 if a.level == "error" else 5)
        if self._screen_live() and a.level == "error":
            self.mission_screen.say(f"✗ {a.message}", "error")

    # -- operations --------------------------------------------------------------------------------
    def submit(
        self,
        op: Any,
        what: str,
        *,
        robot: str | None = None,
        skill: str | None = None,
        expected_revision: int | None = None,
        on_ok: Any = None,
        on_refused: Any = None,
    ) -> None:
        if self.backend is None:
            self.notify("not connected to a mission server", severity="error")
            return
        self.run_worker(
            self._submit(op, what, robot, skill, expected_revision, on_ok, on_refused),
            group="ops",
            exit_on_error=False,
        )

    async def _submit(self, op, what, robot, skill, expected_revision, on_ok, on_refused) -> None:
        screen = self.mission_screen
        if screen is not None:
            screen.say(f"… {what}")
        try:
            reply = await self.backend.submit(op, expected_revision=expected_revision)
        except OperationRefused as e:
            text = refusal_text(e.reply, robot, skill)
            if screen is not None:
                screen.say(f"✗ {what} refused: {text}", "error")
            self.notify(text, title=f"Refused: {what}", severity="error", timeout=8)
            if on_refused is not None:
                on_refused(e.reply)
            return
        except ClientError as e:
            if screen is not None:
                screen.say(f"✗ {what}: {e}", "error")
            self.notify(str(e), title=f"Failed: {what}", severity="error", timeout=8)
            return
        if on_ok is not None:
            on_ok(reply)
        elif screen is not None:
            screen.say(f"✓ {what}", "ok")
        for note in reply.notes:
            self.notify(note, title=what, severity="warning", timeout=8)
