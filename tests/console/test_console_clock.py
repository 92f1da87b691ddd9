"""One mission clock (issue 27): the simulator's time while a sim runs, at its
speed, ticking between reports; wall time otherwise. Every time and duration
shown is said in it: the top bar, ages, delays, the timeline. The wall clock
is injected (never waited out)."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

from console_state import (
    T0,
    fleet_changed,
    inject,
    make_app,
    mars_mid_execution,
    mars_telemetry,
    screen_text,
    wait_until,
)
from map_state import map_message, mars_snapshot

from backend.core.ops import Sync
from backend.protocol.messages import RobotInfo
from console.state.clock import MissionClock, sim_clock_text


def _sim(score: float, sim_time: float, speed: float = 1.0):
    snap = mars_snapshot()
    objects = snap.objects.model_copy(update={"score": score})
    return map_message(
        snap.model_copy(update={"objects": objects, "sim_time": sim_time, "speed": speed})
    )


def test_the_clock_moves_on_at_the_sims_speed_between_reports():
    wall = [T0]
    clock = MissionClock(lambda: wall[0])
    assert not clock.simulated and clock.now_text() == "10:42:07"  # no sim: wall time
    clock.heard(sim_time=1608.0, speed=10.0)
    assert clock.now_text() == "sim 0:26:48"
    wall[0] += timedelta(seconds=6)
    assert clock.now_text() == "sim 0:27:48"
    assert clock.stamp_text(T0 + timedelta(seconds=3)) == "sim 0:27:18"
    assert clock.age_text(T0) == "1m00s" and clock.duration_text(60) == "10m00s"
    clock.heard(sim_time=1667.0, speed=10.0)  # the sim lags a little: the clock waits
    assert clock.now_text() == "sim 0:27:48"
    clock.heard(sim_time=30.0, speed=10.0)  # a new sim run: the clock follows
    assert clock.now_text() == "sim 0:00:30"
    assert sim_clock_text(3725) == "1:02:05" and sim_clock_text(-5) == "-0:00:05"


def test_a_stamp_and_its_mission_time_go_both_ways():
    clock = MissionClock(lambda: T0)
    clock.heard(sim_time=100.0, speed=4.0)
    ts = (T0 + timedelta(seconds=5)).timestamp()
    assert clock.of_ts(ts) == 120.0 and clock.to_ts(120.0) == ts
    assert clock.of(datetime(2026, 3, 14, 10, 42, 2, tzinfo=UTC)) == 80.0


async def test_the_top_bar_shows_the_reported_score_and_the_sim_clock():
    app = make_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        assert "score" not in screen_text(app).splitlines()[0]  # no simulator, no line
        app.post_message(_sim(0.9, 1608.0))
        await wait_until(pilot, lambda: "sim 0:26:48" in screen_text(app), what="the sim clock")
        assert "score 0.9 · sim 0:26:48" in screen_text(app).splitlines()[0]
        app.post_message(_sim(1.9, 1700.0))  # a stone delivered, reported
        await wait_until(pilot, lambda: "score 1.9 · sim 0:28:20" in screen_text(app), what="1.9")


async def test_at_speed_10_every_time_shown_is_sim_time_and_ticks_without_reports():
    b = mars_mid_execution()
    b.engine.clock = lambda: T0
    cid = b.engine.submit(Sync(robot="lru2", through="lru2-6")).value["command"]
    app = make_app()
    wall = [T0]
    app.clock = lambda: wall[0]
    async with app.run_test(size=(200, 40)) as pilot:
        await inject(app, pilot, b, telemetry=mars_telemetry())
        app.post_message(_sim(0.0, 1608.0, speed=10.0))
        far = RobotInfo(name="lru2", online=True, since=T0, heard=T0, delay_s=60.0)
        app.post_message(fleet_changed(far))  # `--link-delay 10m` at speed 10
        await wait_until(pilot, lambda: "sim 0:26:48" in screen_text(app), what="the sim clock")
        screen = app.mission_screen
        screen.schedule.select("lru2-5")
        await pilot.pause()
        assert "⇡1 0s  ⇄10m00s" in screen_text(app)  # the delay in sim time, not 1m00s
        for second, shown in ((1, "0:26:58"), (2, "0:27:08"), (3, "0:27:18")):
            wall[0] = T0 + timedelta(seconds=second)  # no report: 10 sim seconds a second
            screen.freshness_tick()
            await pilot.pause()
            assert f"sim {shown}" in screen_text(app).splitlines()[0]
        text = screen_text(app)
        assert "10m30s ago: ◷" in text  # lru2 as last heard: one link delay + 3 s, in sim time
        # the command was queued at T0, three wall seconds ago: 30 sim seconds
        assert f"sync #{cid} queued 30s ago" in text and "⇡1 30s" in text, text
        await pilot.press("f7")
        await wait_until(pilot, lambda: "timeline" in screen_text(app), what="the timeline")
        app.refresh_plan(force=True)
        await pilot.pause()
        axis = screen_text(app).splitlines()[1]
        assert "10:4" not in axis and any(f"{m}:" in axis for m in range(26, 60)), axis


def test_score_and_sim_clock_80x24(snap_compare):
    async def run(pilot):
        app = pilot.app
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        app.post_message(_sim(0.9, 1608.0))
        await wait_until(pilot, lambda: "score 0.9 · sim 0:26:48" in screen_text(app), what="clock")

    assert snap_compare(make_app(), terminal_size=(80, 24), run_before=run)
