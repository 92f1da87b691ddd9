"""The map screen offline: content, modes, marker operations through a rules
engine, row-cache invalidation, the half-block renderer and the feed follower."""

from __future__ import annotations

import asyncio
import math

import pytest
from console_state import (
    MARS,
    Builder,
    EngineBackend,
    inject,
    make_app,
    map_fed,
    mars_mid_execution,
    mars_telemetry,
    screen_text,
    telemetry_changed,
    wait_until,
)
from map_state import map_message, mars_snapshot
from rich.color import Color as RichColor

from backend.client import mapfollow
from backend.client.mapfollow import MapFeed, MapUpdate
from backend.core.model import Pose, Status
from backend.protocol import mapfeed as mf
from backend.protocol.messages import Telemetry
from console.screens.map import NO_FEED, MapScreen
from console.screens.mission import MissionScreen
from console.widgets.map.view import ROBOT_ARROWS, UPPER_HALF, halfblock_row, heading_glyph

SIZE = (120, 40)


async def open_map(app, pilot, builder=None, *, feed=True):
    await inject(app, pilot, builder or Builder(MARS), telemetry=mars_telemetry())
    if feed:
        app.post_message(map_message())
    await pilot.press("f3")
    await wait_until(pilot, lambda: isinstance(app.screen, MapScreen), 10, "map screen")
    await pilot.pause()


async def test_map_shows_robots_markers_objects_and_legend():
    app = make_app()
    async with app.run_test(size=SIZE) as pilot:
        await open_map(app, pilot)
        text = screen_text(app)
        for needle in (
            "lru1",
            "lru2",
            "POI-B",
            "ROI-north",
            "WIFI-1",
            "◎",
            "wifi_box_1 on",
            "Legend",
            "sampling region",
            "cursor (",
        ):
            assert needle in text, f"{needle!r} not on the map:\n{text}"
        assert NO_FEED not in text
        # lru1 has a queued/idle plan and is online: its label carries the idle glyph
        assert "lru1 ○" in text
        await pilot.press("1")
        assert isinstance(app.screen, MissionScreen)
        await pilot.press("2")
        assert isinstance(app.screen, MapScreen)
        await pilot.press("f2")
        assert isinstance(app.screen, MissionScreen)
        await pilot.press("f3", "escape")
        assert isinstance(app.screen, MissionScreen)


async def test_without_a_feed_the_map_says_so_and_still_shows_robots_and_markers():
    app = make_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await open_map(app, pilot, feed=False)
        app.post_message(map_fed(mf.MapMirror(), MapUpdate("none", detail="no simulator")))
        await wait_until(pilot, lambda: NO_FEED in screen_text(app), 10, "the no-feed notice")
        text = screen_text(app)
        assert "lru1" in text and "ROI-east" in text and "POI-B" in text
        assert "Legend" not in text  # below 100 columns the legend is off until toggled
        await pilot.press("l")
        await pilot.pause()
        assert "Legend" in screen_text(app)


async def test_robot_moving_redraws_only_its_rows():
    app = make_app()
    async with app.run_test(size=SIZE) as pilot:
        await open_map(app, pilot)
        view = app.screen.view
        await pilot.pause()
        before = view.rendered_rows
        row_before = view._overlay.where["robot:lru1"][1]
        t = mars_telemetry()[0]
        app.post_message(
            telemetry_changed(t.model_copy(update={"pose": Pose(x=20.0, y=-30.0, yaw=math.pi / 2)}))
        )
        await pilot.pause()
        await pilot.pause()
        row_after = view._overlay.where["robot:lru1"][1]
        assert row_after != row_before
        redrawn = view.rendered_rows - before
        assert 1 <= redrawn <= 2, redrawn  # the old row and the new row only
        assert heading_glyph(math.pi / 2, ROBOT_ARROWS) == "▲"
        lines = screen_text(app).splitlines()
        assert "▲ lru1" in lines[1 + row_after]


async def test_follow_keeps_the_robot_centred():
    app = make_app()
    async with app.run_test(size=SIZE) as pilot:
        await open_map(app, pilot)
        view = app.screen.view
        await pilot.press("f")
        assert view.follow == "lru1"
        for x, y in ((30.0, 5.0), (60.0, -20.0)):
            app.post_message(
                telemetry_changed(
                    Telemetry(robot="lru1", pose=Pose(x=x, y=y), at=mars_telemetry()[0].at)
                )
            )
            await wait_until(
                pilot,
                lambda x=x, y=y: (view.vp.cx, view.vp.cy) == (x, y),
                10,
                "view centred on lru1",
            )
        col, row = view._overlay.where["robot:lru1"]
        assert abs(col - view.vp.w // 2) <= 1 and abs(row - view.vp.h // 2) <= 1
        assert "following lru1" in screen_text(app)
        await pilot.press("f")
        assert view.follow == "lru2"


async def test_add_bind_move_marker_through_the_rules():
    b = Builder(MARS)
    app = make_app()
    app.backend = EngineBackend(b, app)
    async with app.run_test(size=SIZE) as pilot:
        await inject(app, pilot, b, telemetry=mars_telemetry())
        app.post_message(map_message())
        app.mission_screen.schedule.select("lru2-5")  # drive_to, goal = typed (2, 0)
        await pilot.press("f3")
        await wait_until(pilot, lambda: isinstance(app.screen, MapScreen), 10, "map")
        screen = app.screen
        screen.view.set_cursor(10.0, -20.0)
        await pilot.press("a")
        await wait_until(pilot, lambda: app.screen.query("#name"), 10, "marker prompt")
        app.screen.query_one("#name").value = "GOAL-1"
        await pilot.press("enter")
        await wait_until(pilot, lambda: "GOAL-1" in app.model.mission.markers, 10, "marker added")
        assert app.model.mission.markers["GOAL-1"].pose.x == 10.0
        screen.select_marker("GOAL-1")
        await pilot.press("b")
        await wait_until(
            pilot, lambda: app.model.find("lru2-5")[2].bindings.get("goal") == "GOAL-1", 10, "bound"
        )
        screen.view.set_cursor(14.0, -24.0)
        await pilot.press("m")
        await wait_until(
            pilot,
            lambda: app.model.find("lru2-5")[2].params["goal"]["x"] == 14.0,
            10,
            "idle skill follows",
        )
        assert "lru2-5 follows" in screen.message
        await pilot.pause()
        assert "GOAL-1 ○" in screen_text(app)  # used by an idle skill


@pytest.mark.parametrize("colors", [256, 16])
async def test_ground_classes_stay_apart_in_256_and_16_colours(colors):
    """What the terminal shows (16 colours: after the downgrade a TERM=xterm
    terminal makes): explored ground differs from unexplored, in comms range
    from out of it, and a texture differs from the ground it is drawn on."""
    from console.themes.loader import _to16
    from console.widgets.map.view import T_FREE, T_ROCK, T_SLOW, T_UNKNOWN, MapView

    app = make_app(colors=colors)
    async with app.run_test(size=SIZE) as pilot:
        await open_map(app, pilot)
        view = app.screen.query_one(MapView)
        pal = view._palette()
        shown = (lambda c: _to16(c).triplet) if colors == 16 else (lambda c: c.triplet)
        bg = {k: shown(pal[k]) for k in (T_UNKNOWN, T_FREE, T_SLOW, T_ROCK)}
        bg |= {k + 4: shown(pal[k + 4]) for k in (T_UNKNOWN, T_FREE, T_SLOW, T_ROCK)}
        assert bg[T_FREE] != bg[T_UNKNOWN] and bg[T_FREE + 4] != bg[T_UNKNOWN + 4]
        assert bg[T_FREE] != bg[T_FREE + 4] and bg[T_UNKNOWN + 4] != bg[T_FREE]
        for k in (T_UNKNOWN, T_SLOW, T_ROCK):  # the classes drawn with a texture
            for key in (k, k + 4):
                fg = [
                    s.style.color
                    for s in halfblock_row(
                        [key], [key], pal, pattern=lambda i, _k: "x", textures=view._textures
                    )
                ]
                assert shown(fg[0]) != bg[key], (
                    f"texture of ground {key} invisible in {colors} colours"
                )


def test_halfblock_row_colours_and_merging():
    red, blue, white = (
        RichColor.parse("#ff0000"),
        RichColor.parse("#0000ff"),
        RichColor.parse("#ffffff"),
    )
    pal = {0: red, 1: blue}
    segs = halfblock_row([0, 0, 0, 1], [0, 0, 1, 1], pal)
    assert "".join(s.text for s in segs) == "  " + UPPER_HALF + " "
    assert segs[0].text == "  " and segs[0].style.bgcolor == red  # equal pixels merge into one run
    assert segs[1].style.color == red and segs[1].style.bgcolor == blue  # upper = fg, lower = bg
    assert segs[2].style.bgcolor == blue
    glyph = halfblock_row([1, 1], [1, 0], pal, {1: ("▲", white, True, None)})
    assert (
        glyph[1].text == "▲"
        and glyph[1].style.color == white
        and glyph[1].style.bgcolor == blue
        and glyph[1].style.bold
    )
    patterned = halfblock_row([0, 0], [0, 0], pal, pattern=lambda i, k: "·" if i == 1 else " ")
    assert "".join(s.text for s in patterned) == " ·"


# -- the follower ------------------------------------------------------------------------------


class FakeFeed:
    """The snapshot queryable and the delta subscription, without Zenoh."""

    def __init__(self, snap: mf.MapSnapshot | None):
        self.snap = snap
        self.queries = 0
        self.asked = asyncio.Event()

    async def query(self, session, key, payload, timeout):
        self.queries += 1
        self.asked.set()
        if self.snap is None:
            raise mapfollow.NoResponder("no simulator")
        return mf.dump(self.snap)

    def subscribe(self, session, key, cb):
        return type("Sub", (), {"undeclare": lambda self: None})()


def _delta(seq: int, feed: str = "test", value: int = 3) -> mf.MapDelta:
    import numpy as np

    cells = np.full((16, 16), value, dtype=np.uint8)
    return mf.MapDelta(
        feed=feed,
        seq=seq,
        sim_time=float(seq),
        tiles=[mf.Tile(layer="terrain", tx=0, ty=0, data=mf.encode_tile(cells))],
    )


async def test_follower_applies_deltas_and_resyncs_on_a_gap(monkeypatch):
    fake = FakeFeed(mars_snapshot(seq=3))
    monkeypatch.setattr(mapfollow, "query", fake.query)
    monkeypatch.setattr(mapfollow, "subscribe", fake.subscribe)
    updates: list[MapUpdate] = []
    feed = MapFeed(object(), updates.append)
    await feed.start()
    assert feed.state == "live" and updates[-1].kind == "snapshot" and fake.queries == 1
    feed.got_delta(_delta(4))
    assert feed.mirror.seq == 4 and feed.mirror.layers["terrain"][0, 0] == 3
    assert updates[-1].kind == "delta" and updates[-1].tiles == [("terrain", 0, 0)]
    # seq 5 lost: 6 is a gap -> the snapshot again (now at 6), then 7 applies
    fake.snap = mars_snapshot(seq=6)
    feed.got_delta(_delta(6, value=2))
    await asyncio.wait_for(feed._task, 5)
    assert fake.queries == 2 and feed.mirror.seq == 6 and updates[-1].kind == "snapshot"
    feed.got_delta(_delta(7, value=2))
    assert feed.mirror.seq == 7 and feed.mirror.layers["terrain"][0, 0] == 2
    # another feed run (the sim restarted): resync even though seq looks old
    fake.snap = mars_snapshot(seq=1).model_copy(update={"feed": "second"})
    feed.got_delta(_delta(2, feed="second"))
    await asyncio.wait_for(feed._task, 5)
    assert feed.mirror.feed == "second" and feed.mirror.seq == 2 and fake.queries == 3
    feed.close()


async def test_follower_without_a_sim_asks_again_and_on_the_first_delta(monkeypatch):
    fake = FakeFeed(None)
    monkeypatch.setattr(mapfollow, "query", fake.query)
    monkeypatch.setattr(mapfollow, "subscribe", fake.subscribe)
    updates: list[MapUpdate] = []
    feed = MapFeed(object(), updates.append, retry=0.01)
    await feed.start()
    assert feed.state == "none" and updates[-1].kind == "none"
    fake.asked.clear()
    await asyncio.wait_for(fake.asked.wait(), 5)  # an idle sim sends no deltas: asked again
    assert fake.queries >= 2 and [u.kind for u in updates] == ["none"]  # said once
    fake.snap = mars_snapshot(seq=3)
    feed.got_delta(_delta(4))  # the sim started: query it, keep this delta
    await asyncio.wait_for(feed._task, 5)
    assert feed.state == "live" and feed.mirror.seq == 4
    feed.close()


@pytest.mark.parametrize("status", [Status.RUNNING])
def test_robot_status_glyph_follows_the_active_skill(status):
    from console.widgets.map.view import robot_status

    b = Builder(MARS)
    b.sync("lru1", "lru1-1")
    b.report("lru1", "lru1-1", status.value)
    from console_state import fleet

    from console.state.model import ConsoleModel

    m = ConsoleModel()
    m.load(b.snapshot(), b.library, fleet({"lru1": True, "lru2": False}))
    assert robot_status(m, "lru1") == ("▶", "status-running")
    assert robot_status(m, "lru2") == ("✕", "presence-offline")


async def test_pick_pose_rename_delete_and_a_refusal_on_the_status_line():
    b = mars_mid_execution()
    app = make_app()
    app.backend = EngineBackend(b, app)
    async with app.run_test(size=SIZE) as pilot:
        await inject(app, pilot, b, telemetry=mars_telemetry())
        app.post_message(map_message())
        app.mission_screen.schedule.select("lru2-5")  # drive_to, goal typed
        await pilot.press("f3")
        await wait_until(pilot, lambda: isinstance(app.screen, MapScreen), 10, "map")
        screen = app.screen
        screen.view.set_cursor(-12.0, 7.0)
        await pilot.press("right_square_bracket", "right_square_bracket")  # heading -30°
        await pilot.press("p")
        await wait_until(
            pilot,
            lambda: app.model.find("lru2-5")[2].params["goal"]["x"] == -12.0,
            10,
            "goal picked",
        )
        goal = app.model.find("lru2-5")[2].params["goal"]
        assert goal["y"] == 7.0 and math.isclose(
            goal["yaw"], math.radians(-30) % (2 * math.pi), abs_tol=1e-3
        )
        assert "lru2-5: goal = (-12, 7) heading 330°" in screen.message
        # POI-A is used by lru1-3, which is on the robot: the server refuses its deletion
        screen.select_marker("POI-A")
        await pilot.press("d")
        await wait_until(pilot, lambda: type(app.screen).__name__ == "ConfirmScreen", 10, "confirm")
        await pilot.press("y")
        await wait_until(pilot, lambda: "refused" in screen.message, 10, "refusal shown")
        assert "POI-A" in screen.message and "POI-A" in app.model.mission.markers
        # WIFI-1 is unused: rename it, then delete it
        screen.select_marker("WIFI-1")
        await pilot.press("r")
        await wait_until(pilot, lambda: app.screen.query("#name"), 10, "rename prompt")
        app.screen.query_one("#name").value = "RELAY"
        await pilot.press("enter")
        await wait_until(
            pilot,
            lambda: (
                "RELAY" in app.model.mission.markers and "WIFI-1" not in app.model.mission.markers
            ),
            10,
            "renamed",
        )
        assert screen.view.selected_marker == "RELAY"
        await pilot.press("d")
        await wait_until(pilot, lambda: type(app.screen).__name__ == "ConfirmScreen", 10, "confirm")
        await pilot.press("y")
        await wait_until(pilot, lambda: "RELAY" not in app.model.mission.markers, 10, "deleted")
        await pilot.pause()
        assert "RELAY" not in "\n".join(screen_text(app).splitlines()[1:-4])  # gone from the map
        assert "deleted marker RELAY" in screen.message


async def test_zoom_and_pan_move_the_view():
    app = make_app()
    async with app.run_test(size=SIZE) as pilot:
        await open_map(app, pilot)
        view = app.screen.view
        mpp, cx, cy = view.vp.mpp, view.vp.cx, view.vp.cy
        await pilot.press("plus")
        assert view.vp.mpp == mpp / 2
        await pilot.press("minus", "minus")
        assert view.vp.mpp == mpp * 2
        await pilot.press("shift+right")
        assert view.vp.cx > cx and view.vp.cy == cy
        await pilot.press("shift+up")
        assert view.vp.cy > cy
        await pilot.press("0")
        assert view.vp.mpp >= mpp  # the whole site


async def test_the_mouse_wheel_zooms_about_the_ground_under_the_mouse():
    from textual import events

    from console.widgets.map.view import WHEEL_ZOOM

    app = make_app()
    async with app.run_test(size=SIZE) as pilot:
        await open_map(app, pilot)
        view = app.screen.view
        mpp = view.vp.mpp
        col, row = 20, 8  # away from the centre: the view must shift to keep this ground here
        x, y = view.vp.cell_centre(col, row)

        def wheel(event_type):
            view.post_message(event_type(view, col, row, 0, 0, 0, False, False, False))

        wheel(events.MouseScrollUp)
        await wait_until(pilot, lambda: view.vp.mpp != mpp, 10, "zoomed in")
        assert math.isclose(view.vp.mpp, mpp * WHEEL_ZOOM)
        x2, y2 = view.vp.cell_centre(col, row)
        assert (
            abs(x2 - x) <= view.vp.mpp and abs(y2 - y) <= view.vp.mpp
        )  # the same ground under the mouse
        await wait_until(
            pilot, lambda: f"{view.vp.mpp:.2g} m/px" in screen_text(app), 10, "the new scale shown"
        )
        wheel(events.MouseScrollDown)
        await wait_until(pilot, lambda: math.isclose(view.vp.mpp, mpp), 10, "zoomed back out")


def test_segments_are_clipped_to_the_view():
    from console.widgets.map.view import clip_segment

    (a, b) = clip_segment((-100, 5), (200, 5), 120, 80)
    assert a == pytest.approx((-1.0, 5.0)) and b == pytest.approx((120.0, 5.0))
    assert clip_segment((-100, -5), (-50, -5), 120, 80) is None
    (a, b) = clip_segment((10, 10), (20, 30), 120, 80)
    assert a == (10, 10) and b == (20, 30)  # inside: unchanged


# -- the cursor stays on the site, says what is under it, and no toast covers it (issue 27) --


async def test_the_cursor_stays_on_the_site_and_fit_brings_it_back_to_the_middle():
    app = make_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await open_map(app, pilot)
        view = app.screen.view
        meta = view.mirror.meta
        for _ in range(40):  # ctrl+arrows: 8 cells a press, far beyond the site's corner
            await pilot.press("ctrl+right", "ctrl+down")
        x, y = view.cursor
        assert meta.x0 < x < meta.x0 + meta.width * meta.cell
        assert meta.y0 < y < meta.y0 + meta.height * meta.cell
        assert "off the site" not in screen_text(app)
        await pilot.press("0")  # fit: the whole site, the cursor in its middle
        await pilot.pause()
        assert view.cursor == (view.vp.cx, view.vp.cy)
        assert view.cursor_cell() == (view.vp.w // 2, view.vp.h // 2)


async def test_the_info_line_names_what_is_under_the_cursor():
    app = make_app()
    async with app.run_test(size=(120, 40)) as pilot:
        await open_map(app, pilot)
        view = app.screen.view
        view.set_cursor(45.0, 21.0)  # RSS-A's centre: top score 1 known, explored, no link
        await pilot.pause()
        here = screen_text(app).split("here: ")[1].splitlines()[0]
        assert "region RSS-A (top score 1)" in here, here
        assert "explored: free ground" in here and "in comms coverage" in here, here
        view.set_cursor(20.0, 8.0)  # where lru1 is (telemetry), near the lander's link
        await pilot.pause()
        assert "robot lru1" in screen_text(app)
        view.set_cursor(-150.0, -150.0)  # the far corner: nobody has been there
        await pilot.pause()
        here = screen_text(app).split("here: ")[1].splitlines()[0]
        assert "unexplored" in here and "no comms coverage" in here, here


async def test_a_notification_never_covers_the_cursor():
    app = make_app()
    async with app.run_test(size=(80, 24), notifications=True) as pilot:
        await open_map(app, pilot)
        view = app.screen.view
        # the cursor where toasts come: the bottom-right corner of the map
        view.set_cursor(*view.vp.cell_centre(view.vp.w - 5, view.vp.h - 1))
        await pilot.pause()
        before = view.cursor_cell()
        app.notify("lru2 is out of communication range", title="Alert", timeout=30)
        await wait_until(pilot, lambda: app.screen.query("Toast"), what="a toast")
        await pilot.pause()
        await pilot.pause()
        col, row = view.cursor_cell()
        sx, sy = view.region.x + col, view.region.y + row
        for toast in app.screen.query("Toast"):
            assert not toast.region.contains(sx, sy), (toast.region, (sx, sy))
        assert (col, row) != before  # the view moved the cursor clear of the toast
