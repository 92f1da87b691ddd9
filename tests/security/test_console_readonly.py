"""The console logged in as an observer: read-only mode on the top bar, and
every change action says why it is unavailable (live server with accounts)."""

from __future__ import annotations

import asyncio
import time

from console.app import MissionApp
from console.state.actions import ACTIONS, MUTATING

SIZE = (140, 36)
READ_ONLY = "read-only: logged in as observer watch"


def _app(server, accounts, user: str) -> MissionApp:
    app = MissionApp(connect=server.endpoint, login=accounts.login(user))
    app.animation_level = "none"
    app.cursor_blink = False
    return app


async def _until(pilot, predicate, what: str, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, what
        await pilot.pause(0.05)


def _top(app: MissionApp) -> str:
    return str(app.mission_screen.query_one("#topbar").render())


def test_observer_console_is_read_only_and_says_why(server, accounts):
    async def scenario() -> None:
        app = _app(server, accounts, "watch")
        async with app.run_test(size=SIZE) as pilot:
            screen = app.mission_screen
            await _until(
                pilot, lambda: app.model.read_only and app.model.mission is not None, "logged in"
            )
            # the top bar redraws on the screen's turn, after the model took the account
            await _until(pilot, lambda: READ_ONLY in _top(app), "the top bar says read-only")
            screen.schedule.select("lru1-1")
            await pilot.pause()
            changing = [a.name for a in ACTIONS if a.name in MUTATING]
            assert changing and all(screen.why_disabled(a) == READ_ONLY for a in changing)
            assert (
                app.model.read_only_reason("lru1-1") == "logged in as observer watch"
            )  # the parameter editor too
            await pilot.press("d")  # a disabled key: the reason on the status line, nothing sent
            await _until(pilot, lambda: READ_ONLY in screen.message, "reason on the status line")

        ops = _app(server, accounts, "ops")
        async with ops.run_test(size=SIZE) as pilot:
            await _until(
                pilot,
                lambda: ops.model.connection == "connected" and ops.model.mission is not None,
                "operator connected",
            )
            await pilot.pause()
            assert ops.model.read_only == "" and "read-only" not in _top(ops)
            ops.mission_screen.schedule.select("lru1-1")
            await pilot.pause()
            assert ops.mission_screen.why_disabled("delete") is None

    asyncio.run(asyncio.wait_for(scenario(), 90))
