"""A robot's contact state on the console (issue 34): out of contact (its
window closed, the next one opens at T, in mission time) in the schedule's
header, the fleet table and the link in words; its last known state drawn as
such; a robot without windows shows nothing new. State injected as messages,
the clock pinned."""

from __future__ import annotations

from datetime import timedelta

from console_state import (
    MARS_FLEET,
    T0,
    fleet,
    fleet_changed,
    inject,
    make_app,
    mars_mid_execution,
    mars_telemetry,
    screen_text,
    telemetry_changed,
    wait_until,
)
from map_state import map_message, mars_snapshot

from backend.protocol.messages import RobotContact, RobotInfo
from console.state.clock import MissionClock
from console.state.contact import (
    CONTACT_GLYPH,
    contact_words,
    header_contact,
    presence_words,
)
from console.state.model import ConsoleModel
from console.state.text import GLYPHS
from console.widgets.map.view import OFFLINE_GLYPH, robot_status

CLOSED = RobotContact(state="out_of_contact", next_contact=1200.0, clock="sim", source="sim")
OPEN = RobotContact(state="in_contact", closes=1920.0, clock="sim", source="sim")
ALWAYS = RobotContact(state="in_contact")


def _info(contact: RobotContact | None, *, online: bool = True, heard=T0) -> RobotInfo:
    return RobotInfo(name="lru1", online=online, since=T0, heard=heard, contact=contact)


def _model(now=T0) -> ConsoleModel:
    m = ConsoleModel(clock=MissionClock(lambda: now))
    b = mars_mid_execution()
    m.load(b.snapshot(), b.library, fleet(MARS_FLEET))
    for t in mars_telemetry():
        m.set_telemetry(t)
    return m


def test_out_of_contact_is_said_with_the_next_window_in_mission_time():
    clock = MissionClock(lambda: T0)
    closed = _info(CLOSED)
    assert header_contact(closed, clock, 20) == f"{CONTACT_GLYPH} next sim 0:20:00"
    assert header_contact(closed, clock, 17) == f"{CONTACT_GLYPH} → sim 0:20:00"  # 80 columns
    assert header_contact(closed, clock, 14) == f"{CONTACT_GLYPH} →sim 0:20:00"
    assert header_contact(closed, clock, 13) == f"{CONTACT_GLYPH} sim 0:20:00"
    assert header_contact(closed, clock, 3) == CONTACT_GLYPH
    assert contact_words(closed, clock) == "out of contact: window closed, next contact sim 0:20:00"
    assert presence_words(closed, clock) == f"{CONTACT_GLYPH} out of contact, next sim 0:20:00"
    never = _info(CLOSED.model_copy(update={"next_contact": None}))
    assert header_contact(never, clock, 15) == f"{CONTACT_GLYPH} no contact"
    assert contact_words(never, clock) == "out of contact: window closed, no window ahead"


def test_in_contact_with_windows_says_until_when_and_without_windows_nothing():
    clock = MissionClock(lambda: T0)
    assert header_contact(_info(OPEN), clock, 20) == "● until sim 0:32:00"
    assert header_contact(_info(OPEN), clock, 10) == ""  # the caller's "● online" stands
    assert contact_words(_info(OPEN), clock) == "in contact until sim 0:32:00"
    for info in (_info(ALWAYS), _info(None), _info(CLOSED, online=False)):
        assert header_contact(info, clock, 40) == contact_words(info, clock) == ""
        assert presence_words(info, clock) == ""


def test_a_wall_clock_window_is_said_in_the_consoles_mission_time():
    clock = MissionClock(lambda: T0)
    wall = RobotContact(
        state="out_of_contact", next_contact=(T0 + timedelta(minutes=5)).timestamp()
    )
    assert contact_words(_info(wall), clock).endswith(
        "next contact " + clock.ts_text((T0 + timedelta(minutes=5)).timestamp())
    )
    clock.heard(sim_time=600.0, speed=1.0)  # a sim runs: mission time is its time
    assert contact_words(_info(wall), clock).endswith("next contact sim 0:15:00")


def test_a_robot_out_of_contact_is_its_last_known_state():
    m = _model(T0 + timedelta(seconds=3))
    assert not m.freshness("lru1").stale
    m.set_robot(_info(CLOSED))
    m.heard["lru1"] = T0  # its last telemetry
    fresh = m.freshness("lru1")
    assert fresh.stale and fresh.why == "out of contact" and fresh.age_s == 3.0
    m.set_robot(_info(ALWAYS))  # its window opened: heard
    assert not m.freshness("lru1").stale
    m.set_robot(_info(CLOSED, online=False))  # offline wins
    assert m.freshness("lru1").why == "offline"


def test_on_the_map_a_robot_out_of_contact_is_drawn_apart():
    m = _model()
    assert robot_status(m, "lru1")[0] == GLYPHS[m.robot_state("lru1")[0].status]
    m.set_robot(_info(CLOSED))
    assert robot_status(m, "lru1") == (CONTACT_GLYPH, "presence-unknown")
    m.set_robot(_info(CLOSED, online=False))
    assert robot_status(m, "lru1")[0] == OFFLINE_GLYPH


async def _closed_window(app, pilot):
    """Mid-execution under a sim, now at 0:18:20; lru1's window closed at 0:12:00, when it
    was last heard (6m20s ago); the others still heard."""
    now = [T0]
    app.clock = lambda: now[0]
    await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
    now[0] = T0 + timedelta(seconds=380)
    snap = mars_snapshot()
    app.post_message(map_message(snap.model_copy(update={"sim_time": 1100.0, "speed": 1.0})))
    app.post_message(fleet_changed(_info(CLOSED, heard=T0)))
    for t in mars_telemetry():
        if t.robot != "lru1":
            app.post_message(telemetry_changed(t.model_copy(update={"at": now[0]})))
    await wait_until(pilot, lambda: "sim 0:20:00" in screen_text(app), what="the header")
    app.mission_screen.freshness_tick()
    await pilot.pause()


async def test_the_schedule_and_the_fleet_say_when_the_next_window_opens():
    app = make_app()
    async with app.run_test(size=(120, 40)) as pilot:
        await _closed_window(app, pilot)
        text = screen_text(app)
        assert f"{CONTACT_GLYPH} →sim 0:20:00│" in text, text  # its column is narrow
        # drawn as last known, as of when it was heard, with what it probably does now
        assert "6m20s ago ≈ lru1-" in text, text
        assert "● online" in text  # the others: as before
        await pilot.press("f4")
        await pilot.pause()
        table = app.screen.query_one("DataTable")
        table.move_cursor(row=app.screen.shown.index("lru1"))
        await pilot.pause()
        text = screen_text(app)
        assert f"{CONTACT_GLYPH} out of contact, next sim 0:20:00" in text, text
        assert "link: out of contact: window closed, next contact sim 0:20:00 · heard" in text
        assert "4 robots, 2 online, 1 out of contact" in text, text


def test_robot_out_of_contact_80x24(snap_compare):
    async def run(pilot):
        app = pilot.app
        await _closed_window(app, pilot)
        text = screen_text(app)
        assert f"{CONTACT_GLYPH} → sim 0:20:00│" in text and "6m20s ago:" in text, text

    assert snap_compare(make_app(), terminal_size=(80, 24), run_before=run)
