"""The map screen against a REAL mission server (subprocess), with robot
agents or the simulated fleet (subprocesses), driven with keys."""

from __future__ import annotations

import numpy as np
import pytest
from console_live import running
from console_state import MARS, TUTORIAL, make_app, screen_text, wait_until

from backend import transport
from backend.core.model import Status
from backend.protocol import mapfeed as mf
from console.screens.map import MapScreen

SIZE = (120, 40)
SLOW = 30.0


def skill(app, sid):
    found = app.model.find(sid)
    return found[2] if found else None


@pytest.fixture
def live(tmp_path):
    with running(tmp_path, TUTORIAL) as env:
        yield env


@pytest.fixture
def live_sim(tmp_path):
    with running(tmp_path, MARS) as env:
        yield env


async def to_schedule_and_select(app, pilot, sid):
    await pilot.press("f2")
    app.mission_screen.schedule.select(sid)
    await pilot.pause()
    await pilot.press("f3")
    await wait_until(pilot, lambda: isinstance(app.screen, MapScreen), SLOW, "map screen")


async def test_marker_placed_bound_moved_idle_follows_synchronized_keeps_old_value(live):
    live.start_robots()
    app = make_app(connect=live.endpoint, user="op1")
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(
            pilot,
            lambda: (
                app.model.connected and app.model.is_online("lru1") and app.model.is_online("lru2")
            ),
            SLOW,
            "connected, robots online",
        )
        await to_schedule_and_select(app, pilot, "lru2-1")  # drive_to with a typed goal
        screen = app.screen
        await wait_until(pilot, lambda: "no map feed" in screen_text(app), SLOW, "no sim: said so")
        screen.view.set_cursor(20.0, -10.0)
        await pilot.press("a")
        await wait_until(pilot, lambda: app.screen.query("#name"), SLOW, "marker prompt")
        app.screen.query_one("#name").value = "GOAL-1"
        await pilot.press("enter")
        await wait_until(
            pilot, lambda: "GOAL-1" in app.model.mission.markers, SLOW, "marker added on the server"
        )
        screen.select_marker("GOAL-1")
        await pilot.press("b")
        await wait_until(
            pilot,
            lambda: skill(app, "lru2-1").bindings.get("goal") == "GOAL-1",
            SLOW,
            "lru2-1 bound",
        )
        await to_schedule_and_select(app, pilot, "lru1-1")  # drive_to bound to POI-A
        screen.select_marker("GOAL-1")
        await pilot.press("b")
        await wait_until(
            pilot,
            lambda: skill(app, "lru1-1").bindings.get("goal") == "GOAL-1",
            SLOW,
            "lru1-1 bound",
        )
        # lru2-1 goes to the robot; lru1-1 stays in the plan
        await pilot.press("f2")
        app.mission_screen.schedule.select("lru2-1")
        await pilot.press("s")
        await wait_until(
            pilot,
            lambda: skill(app, "lru2-1").status == Status.IDLE_SYNCHRONIZED,
            SLOW,
            "lru2-1 synchronized",
        )
        await pilot.press("f3")
        await wait_until(pilot, lambda: isinstance(app.screen, MapScreen), SLOW, "map again")
        await wait_until(
            pilot, lambda: "GOAL-1 ●" in screen_text(app), SLOW, "marker shown as used on a robot"
        )
        screen.select_marker("GOAL-1")
        screen.view.set_cursor(30.0, -15.0)
        await pilot.press("m")
        await wait_until(
            pilot,
            lambda: skill(app, "lru1-1").params["goal"]["x"] == 30.0,
            SLOW,
            "the idle skill follows",
        )
        assert skill(app, "lru2-1").params["goal"]["x"] == 20.0  # on the robot: unchanged
        await wait_until(
            pilot, lambda: "lru2-1 still uses the old value" in screen.message, SLOW, "reply shown"
        )
        assert "lru1-1 follows" in screen.message
        assert "unsynchronize" in screen.message


async def test_follow_a_robot_and_the_mirror_matches_the_sim(live_sim):
    live_sim.start_sim(speed=40)
    app = make_app(connect=live_sim.endpoint)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(
            pilot,
            lambda: app.model.connected and app.model.is_online("lru1"),
            SLOW,
            "sim robots online",
        )
        feed = app.bridge.map_feed
        await wait_until(
            pilot, lambda: feed is not None and feed.state == "live", SLOW, "map feed live"
        )
        start = feed.mirror.seq
        await pilot.press("f3")
        await wait_until(
            pilot,
            lambda: isinstance(app.screen, MapScreen) and "lander" in screen_text(app),
            SLOW,
            "map with the lander",
        )
        # lru1 drives to POI-A (42, 18) while the map follows it
        await pilot.press("f2")
        app.mission_screen.schedule.select("lru1-1")
        await pilot.press("s")
        await wait_until(
            pilot,
            lambda: skill(app, "lru1-1").status == Status.IDLE_SYNCHRONIZED,
            SLOW,
            "synchronized",
        )
        await pilot.press("r")
        await pilot.press("f3")
        await wait_until(pilot, lambda: isinstance(app.screen, MapScreen), SLOW, "map")
        view = app.screen.view
        await pilot.press("f")
        assert view.follow == "lru1"
        x0 = app.model.telemetry["lru1"].pose.x

        def centred() -> bool:
            t = app.model.telemetry["lru1"]
            col, row = view.vp.to_cell(t.pose.x, t.pose.y)
            return (
                t.pose.x > x0 + 5
                and abs(col - view.vp.w // 2) <= 1
                and abs(row - view.vp.h // 2) <= 1
            )

        await wait_until(pilot, centred, SLOW, "the view tracks lru1 as it drives")
        await wait_until(pilot, lambda: "following lru1" in screen_text(app), SLOW, "said")
        # the console's mirror equals the sim's world (a fresh snapshot) after deltas
        await wait_until(pilot, lambda: feed.mirror.seq > start, SLOW, "deltas applied")
        session = app.bridge.client.session
        for _attempt in range(100):  # the sim goes on: until a snapshot and the mirror meet
            snap = mf.MapSnapshot.model_validate_json(
                await transport.query(session, mf.KEY_MAP_SNAPSHOT, b"", 10.0)
            )
            await wait_until(
                pilot, lambda snap=snap: feed.mirror.seq >= snap.seq, SLOW, "mirror caught up"
            )
            if feed.mirror.seq == snap.seq:
                break
        assert feed.mirror.seq == snap.seq
        truth = mf.MapMirror()
        truth.apply_snapshot(snap)
        for layer in ("terrain", "coverage"):
            assert np.array_equal(feed.mirror.layers[layer], truth.layers[layer]), layer
        assert feed.mirror.objects == truth.objects
        assert (feed.mirror.layers["terrain"] != mf.T_UNKNOWN).any()
