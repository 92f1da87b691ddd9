"""A command's verification stage on the console (issue 34.2): the stage each
command waits for and when it is due, where its pending commands are shown
(the fleet's link line, the schedule's uplinking rows, an executing command's
skills). State injected as messages, the clock pinned."""

from __future__ import annotations

from datetime import timedelta

from console_state import T0, fleet_changed, inject, make_app, mars_telemetry, screen_text
from test_console_link import _with_pending_sync

from backend.core.ops import Predicted
from backend.core.verification import Path, verify
from backend.protocol.messages import RobotInfo
from console.state import link
from console.state.clock import MissionClock


def _far(b, cid, now, delay_s=20.0):
    """lru2 as the server publishes it: its command's stages verified at `now`."""
    c = b.mission.command(cid)
    plan = {"lru2-5": Predicted(start=T0 + timedelta(minutes=2), end=T0 + timedelta(minutes=9))}
    v = verify(c, b.mission, Path(delay_s), plan, now)
    return RobotInfo(
        name="lru2", online=True, since=T0, heard=now, delay_s=delay_s, verification=[v]
    )


class _Model:
    def __init__(self, b, info):
        self.robots = {"lru2": info}
        self._b = b

    def pending(self, robot):
        return self._b.mission.pending_commands(robot)


def test_the_link_line_says_the_stage_waited_for_and_its_due():
    b, cid = _with_pending_sync()
    now = T0 + timedelta(seconds=30)
    clock = MissionClock(lambda: now)
    text = link.link_text(_Model(b, _far(b, cid, now)), "lru2", clock)
    due = clock.stamp_text(T0 + timedelta(seconds=40))  # there and back: 2 x 20 s
    assert f"sync #{cid} queued 30s ago (sent due {due})" in text, text
    late = T0 + timedelta(seconds=90)
    overdue = link.link_text(_Model(b, _far(b, cid, late)), "lru2", MissionClock(lambda: late))
    assert f"sync #{cid} queued 1m30s ago (sent ⚠ OVERDUE 50s)" in overdue, overdue


async def test_the_fleet_shows_a_pending_commands_stage():
    from console.screens.fleet import FleetScreen

    b, cid = _with_pending_sync()
    app = make_app()
    now = T0 + timedelta(seconds=30)
    app.clock = lambda: now
    async with app.run_test(size=(140, 40)) as pilot:
        await inject(app, pilot, b, telemetry=mars_telemetry())
        app.post_message(fleet_changed(_far(b, cid, now)))
        await pilot.press("f4")
        await pilot.pause()
        assert isinstance(app.screen, FleetScreen)
        app.screen.query_one("DataTable").move_cursor(row=app.screen.shown.index("lru2"))
        await pilot.pause()
        text = screen_text(app)
        due = app.model.clock.stamp_text(T0 + timedelta(seconds=40))
        assert f"sync #{cid} queued 30s ago (sent due {due})" in text, text


async def test_an_executing_commands_skill_says_the_stage_waited_for():
    from console_state import mars_mid_execution

    from backend.core.verification import Stage, Verification

    due = T0 + timedelta(minutes=5)
    stages = [Stage(name=n, state="ok", at=T0) for n in ("queued", "sent", "received")]
    stages += [Stage(name="started", state="ok", at=T0)]
    stages += [Stage(name="completed", state="waiting", due=due, tolerance_s=2.0)]
    v = Verification(command=7, robot="lru1", op="sync", skills=["lru1-2"], stages=stages)
    app = make_app()
    now = T0 + timedelta(seconds=30)
    app.clock = lambda: now
    async with app.run_test(size=(240, 40)) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        info = RobotInfo(name="lru1", online=True, since=T0, heard=now, verification=[v])
        app.post_message(fleet_changed(info))
        await pilot.pause()
        await pilot.pause()
        words = f"completed due {app.model.clock.stamp_text(due)}"
        rows = [line.split("│")[0] for line in screen_text(app).splitlines()]
        assert any("explore" in r and words in r for r in rows), rows
