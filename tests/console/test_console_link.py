"""The robot link on the console (issue 19): commands waiting for their robot
(⇡ on the skills a pending sync carries, with the command's age; a count and
the oldest age in the column's header), the robot's one-way delay (⇄), and a
robot far enough away drawn as its last known state. State injected as
messages, the clock pinned."""

from __future__ import annotations

from datetime import timedelta

from console_state import (
    MARS_FLEET,
    T0,
    fleet_changed,
    inject,
    make_app,
    mars_mid_execution,
    mars_telemetry,
    screen_text,
    wait_until,
)

from backend.core.model import CommandState
from backend.core.ops import Sync
from backend.protocol.messages import RobotInfo
from console.state import link
from console.state.clock import MissionClock
from console.state.freshness import SILENT_AFTER_S


def _with_pending_sync():
    """Mid-execution, then lru2 asked to take lru2-5 and lru2-6 (command queued at T0)."""
    b = mars_mid_execution()
    b.engine.clock = lambda: T0
    applied = b.engine.submit(Sync(robot="lru2", through="lru2-6"))
    assert applied.value["skills"] == ["lru2-5", "lru2-6"]
    return b, applied.value["command"]


def test_how_a_command_and_a_delay_are_said():
    b, cid = _with_pending_sync()
    c = b.mission.command(cid)
    later = MissionClock(lambda: T0 + timedelta(seconds=40))
    assert link.command_text(c, later) == f"sync #{cid} queued 40s ago"
    sent = c.model_copy(
        update={
            "state": CommandState.SENT,
            "sent": T0 + timedelta(seconds=30),
            "expires": T0 + timedelta(minutes=30),
        }
    )
    # a sent command's age counts from its transmission, not from when it was queued
    assert link.command_text(sent, later) == f"sync #{cid} sent 10s ago, expires in 29m20s"
    assert link.pending_text([c, sent], later) == "⇡2 40s"  # waiting since queued
    assert link.pending_text([], later) == ""
    assert link.delay_text(0.2, later) == "" and link.delay_text(20, later) == "⇄20s"
    assert link.delay_text(1200, later) == "⇄20m00s"
    assert link.uplinking(b.mission) == {"lru2-5": c, "lru2-6": c}


def test_at_a_sims_speed_ages_and_delays_are_said_in_sim_time():
    b, cid = _with_pending_sync()
    c = b.mission.command(cid)
    clock = MissionClock(lambda: T0 + timedelta(seconds=40))
    clock.heard(sim_time=1200.0, speed=10.0)
    # `--link-delay 10m` at speed 10: the robot's one-way delay is 60 wall seconds
    assert link.delay_text(60, clock) == "⇄10m00s"
    assert link.command_text(c, clock) == f"sync #{cid} queued 6m40s ago"
    assert link.pending_text([c], clock) == "⇡1 6m40s"


async def test_a_pending_sync_shows_on_its_skills_and_header_and_locks_them():
    b, cid = _with_pending_sync()
    app = make_app()
    now = [T0 + timedelta(seconds=40)]  # the command was queued at T0
    app.clock = lambda: now[0]
    async with app.run_test(size=(200, 40)) as pilot:
        await inject(app, pilot, b, telemetry=mars_telemetry())
        text = screen_text(app)
        assert "⇡ back to lander" in text and f"sync #{cid} queued 40s ago" in text, text
        assert "⇡1 40s" in text  # lru2's header
        m = app.model
        assert m.why_not("delete", "lru2", "lru2-5").startswith(
            f"command {cid} (sync lru2-5, lru2-6) to lru2 is waiting for the robot's answer"
        )
        assert "(w on the schedule)" in m.read_only_reason("lru2-6")  # the console's key
        assert m.why_not("run", "lru1", None)  # lru1 runs lru1-2 already
        assert "queued 40s ago" in m.quit_risks()[1]
        now[0] += timedelta(seconds=5)  # the ages count up without a message
        app.mission_screen.freshness_tick()
        await pilot.pause()
        assert "⇡1 45s" in screen_text(app) and f"sync #{cid} queued 45s ago" in screen_text(app)


async def test_a_distant_robot_shows_its_delay_and_is_drawn_as_of_then():
    b = mars_mid_execution()
    app = make_app()
    async with app.run_test(size=(120, 40)) as pilot:
        await inject(app, pilot, b, telemetry=mars_telemetry())
        far = RobotInfo(name="lru1", online=True, since=T0, heard=T0, delay_s=4.0)
        app.post_message(fleet_changed(far))
        await pilot.pause()
        assert "⇄4s" in screen_text(app)
        assert not app.model.freshness("lru1").stale  # 4 s: live enough
        mars = RobotInfo(name="lru1", online=True, since=T0, heard=T0, delay_s=600.0)
        app.post_message(fleet_changed(mars))
        await pilot.pause()
        fresh = app.model.freshness("lru1")
        assert fresh.stale and fresh.why == "delayed" and fresh.age_s == 600.0
        app.mission_screen.freshness_tick()
        await pilot.pause()
        assert "10m00s ago ≈ lru1" in screen_text(app), screen_text(app)
        assert "⇄10m00s" in screen_text(app)


def test_the_server_hearing_a_robot_counts_as_heard():
    b = mars_mid_execution()
    from console_state import fleet

    from console.state.model import ConsoleModel

    m = ConsoleModel(clock=MissionClock(lambda: T0 + timedelta(seconds=SILENT_AFTER_S + 5)))
    m.load(b.snapshot(), b.library, fleet(MARS_FLEET))
    for t in mars_telemetry():
        m.set_telemetry(t)
        m.heard[t.robot] = T0
    assert m.freshness("lru1").why == "silent"  # the console heard nothing for 15 s
    m.set_robot(RobotInfo(name="lru1", online=True, since=T0, heard=T0 + timedelta(seconds=14)))
    assert not m.freshness("lru1").stale  # the server did, a second ago


def test_pending_sync_and_delay_80x24(snap_compare):
    b, _ = _with_pending_sync()

    async def run(pilot):
        app = pilot.app
        now = T0 + timedelta(seconds=40)  # the command was queued at T0
        app.clock = lambda: now
        await inject(app, pilot, b, telemetry=mars_telemetry())
        app.post_message(
            fleet_changed(RobotInfo(name="lru2", online=True, since=T0, heard=now, delay_s=2.0))
        )
        await pilot.pause()
        app.mission_screen.schedule.select("lru2-5")
        app.mission_screen.freshness_tick()
        await pilot.pause()
        text = screen_text(app)
        assert "⇡1 40s  ⇄2s" in text and "⇡ back to lander" in text, text
        assert "lru2-5: sync #" in text and "queued 40s ago, waiting for lru2's answer" in text
        assert "s Sync" not in text  # it is being synchronized: nothing to sync there

    assert snap_compare(make_app(), terminal_size=(80, 24), run_before=run)


async def test_the_fleet_screen_lists_each_robots_commands_and_delay():
    from console.screens.fleet import FleetScreen

    b, cid = _with_pending_sync()
    app = make_app()
    now = T0 + timedelta(seconds=40)
    app.clock = lambda: now
    async with app.run_test(size=(120, 40)) as pilot:
        await inject(app, pilot, b, telemetry=mars_telemetry())
        far = RobotInfo(name="lru2", online=True, since=T0, heard=now, delay_s=20.0)
        app.post_message(fleet_changed(far))
        await pilot.press("f4")
        await pilot.pause()
        assert isinstance(app.screen, FleetScreen)
        app.screen.query_one("DataTable").move_cursor(row=app.screen.shown.index("lru2"))
        await pilot.pause()
        text = screen_text(app)
        assert "⇡1 40s ⇄20s" in text, text
        assert (
            f"link: one-way delay 20s · heard 0s ago · waiting for its answer: "
            f"sync #{cid} queued 40s ago" in text
        ), text


def test_the_event_log_says_what_became_of_a_command():
    from console_state import fleet

    from console.state.eventlog import EventLog
    from console.state.model import ConsoleModel

    b = mars_mid_execution()
    b.engine.clock = lambda: T0
    m = ConsoleModel(clock=MissionClock(lambda: T0))
    m.load(b.snapshot(), b.library, fleet(MARS_FLEET))
    queued = b.engine.submit(Sync(robot="lru2", through="lru2-6")).batch()
    m.apply(queued)
    log = EventLog()
    [entry] = log.add_batch(queued, m, T0)
    assert "command 1 (sync lru2-5, lru2-6) queued for lru2" in entry.text, entry.text


async def test_a_pending_sync_is_cancelled_from_the_schedule_with_a_confirmation():
    from console_state import EngineBackend

    from console.screens.dialogs import ConfirmScreen

    b, cid = _with_pending_sync()
    app = make_app()
    app.backend = EngineBackend(b, app)
    async with app.run_test(size=(120, 40)) as pilot:
        await inject(app, pilot, b, telemetry=mars_telemetry())
        screen = app.mission_screen
        screen.schedule.select("lru2-5")
        await pilot.pause()
        cancel = app.model.keys.say("mission.cancel")
        assert f"({cancel} cancels it)" in screen_text(app)  # the status line names the key
        reason = app.model.read_only_reason("lru2-6")
        assert f"({cancel} on the schedule)" in reason and "ctl cancel" not in reason
        await pilot.press(app.model.keys.keys("mission.cancel"))
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="confirm")
        text = screen_text(app)
        assert f"Cancel sync #{cid} to lru2 (lru2-5, lru2-6)?" in text, text
        assert "withdrawn at once" in text  # it never left
        await pilot.press("y")
        await wait_until(
            pilot, lambda: b.mission.command(cid).state == CommandState.CANCELLED, what="cancelled"
        )
        await wait_until(pilot, lambda: app.model.uplinking("lru2-5") is None, what="unlocked")
        assert f"sync #{cid} to lru2 cancelled" in str(screen.message)


async def test_the_fleet_and_the_palette_cancel_a_pending_command():
    from console_state import EngineBackend

    from console.commands import MissionCommands
    from console.screens.dialogs import ConfirmScreen
    from console.screens.fleet import FleetScreen

    b, cid = _with_pending_sync()
    app = make_app()
    app.backend = EngineBackend(b, app)
    async with app.run_test(size=(120, 40)) as pilot:
        await inject(app, pilot, b, telemetry=mars_telemetry())
        hits = [h async for h in MissionCommands(app.screen).search("cancel sync")]
        assert any(f"Cancel sync #{cid} to lru2 (lru2-5, lru2-6)" in h.text for h in hits)
        await pilot.press("f4")
        await wait_until(pilot, lambda: isinstance(app.screen, FleetScreen), what="fleet")
        fleet = app.screen
        fleet.query_one("DataTable").move_cursor(row=fleet.shown.index("lru2"))
        await pilot.pause()
        await pilot.press(app.model.keys.keys("fleet.cancel"))
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="confirm")
        assert f"Cancel sync #{cid} to lru2" in screen_text(app)
        await pilot.press("n")  # kept
        await pilot.pause()
        assert b.mission.command(cid).pending
        hits = [h async for h in MissionCommands(fleet).search("cancel sync")]
        [hit] = [h for h in hits if h.text.startswith(f"Cancel sync #{cid}")]
        hit.command()  # what choosing it in the palette runs
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="confirm")
        await pilot.press("y")
        await wait_until(
            pilot, lambda: b.mission.command(cid).state == CommandState.CANCELLED, what="cancelled"
        )
