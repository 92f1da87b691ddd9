"""End-to-end: a live robot fails a skill (label "[fail]", see
console_robots.py); the console raises one alert — its own from the report,
merged with the server's — rings the bell, shows the badge, and the operator
acknowledges it on the alert list."""

from __future__ import annotations

import pytest
from console_live import Live
from console_state import TUTORIAL, make_app, screen_text, wait_until

from backend.model import Status
from console.alertview import AlertScreen

SIZE = (120, 32)
SLOW = 30.0


@pytest.fixture
def live(tmp_path):
    env = Live(tmp_path, TUTORIAL)
    env.start_server()
    try:
        yield env
    finally:
        env.close()


def status(app, sid):
    found = app.model.find(sid)
    return found[2].status if found else None


async def test_workflow_injected_failure_raises_an_alert_that_is_acknowledged(live):
    live.start_robots()
    app = make_app(connect=live.endpoint, user="ada")
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, lambda: app.model.connected and app.model.is_online("lru1"), SLOW, "connected, lru1 online")
        screen = app.mission_screen
        screen.schedule.select("lru1-1")
        await pilot.pause()
        editor = screen.editor
        await wait_until(pilot, lambda: editor.skill_id == "lru1-1" and editor.query("#f-label"), SLOW, "editor")
        editor.query_one("#f-label").value = "drive [fail]"
        await pilot.pause()
        editor.action_apply()
        await wait_until(pilot, lambda: app.model.find("lru1-1")[2].label == "drive [fail]", SLOW, "label applied")
        screen.schedule.select("lru1-1")
        screen.schedule.focus()
        await pilot.pause()
        bells = app.bells
        await pilot.press("s")
        await wait_until(pilot, lambda: status(app, "lru1-1") == Status.IDLE_SYNCHRONIZED, SLOW, "synchronized")
        await pilot.press("r")
        await wait_until(pilot, lambda: status(app, "lru1-1") == Status.FAILURE, SLOW, "failed")
        await wait_until(pilot, lambda: any(a.kind == "failure" for a in app.alerts.alerts), SLOW, "failure alert")
        # the server's alert about the same failure arrives too: merged, not a second alert
        await wait_until(pilot, lambda: [a.source for a in app.alerts.alerts if a.kind == "failure"] == ["both"], SLOW, "server alert merged")
        failure = [a for a in app.alerts.alerts if a.kind == "failure"]
        assert len(failure) == 1 and failure[0].skill == "lru1-1" and failure[0].level == "error"
        assert app.bells == bells + 1  # one bell for one failure
        assert "⚠ 1 alert (F6)" in screen_text(app)
        # the log names who synchronized: this console's user and client id
        sync = [e for e in app.event_log.entries if e.op == "sync_ack"]
        assert sync and sync[-1].user == "ada" and sync[-1].client == app.bridge.client.client_id
        assert any(e.kind == "failure" and e.skill == "lru1-1" for e in app.event_log.entries)
        await pilot.press("f6")
        await wait_until(pilot, lambda: isinstance(app.screen, AlertScreen), SLOW, "alert list")
        assert "simulated failure of drive_to" in screen_text(app)
        await pilot.press("enter")
        await wait_until(pilot, lambda: app.alerts.unacknowledged == 0, SLOW, "acknowledged")
        assert "0 unacknowledged of 1" in screen_text(app)
        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen is app.mission_screen, SLOW, "back to the schedule")
        assert "⚠" not in screen_text(app).splitlines()[0]
