"""A robot's contact state on the console (issue 34): out of contact (its
window closed, the next one opens at T, in mission time) in the schedule's
header, the fleet table and the link in words; its last known state drawn as
such; a robot without windows shows nothing new. State injected as messages,
the clock pinned."""

from __future__ import annotations

from datetime import timedelta

from console_state import MARS_FLEET, T0, fleet, mars_mid_execution, mars_telemetry

from backend.protocol.messages import RobotContact, RobotInfo
from console.state.clock import MissionClock
from console.state.contact import (
    CONTACT_GLYPH,
    contact_words,
    header_contact,
    presence_words,
)
from console.state.model import ConsoleModel

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
    assert header_contact(closed, clock, 20) == f"{CONTACT_GLYPH} next sim 20:00"
    assert header_contact(closed, clock, 15) == f"{CONTACT_GLYPH} → sim 20:00"  # 80 columns
    assert header_contact(closed, clock, 12) == f"{CONTACT_GLYPH} sim 20:00"
    assert header_contact(closed, clock, 3) == CONTACT_GLYPH
    assert contact_words(closed, clock) == "out of contact: window closed, next contact sim 20:00"
    assert presence_words(closed, clock) == f"{CONTACT_GLYPH} out of contact, next sim 20:00"
    never = _info(CLOSED.model_copy(update={"next_contact": None}))
    assert header_contact(never, clock, 15) == f"{CONTACT_GLYPH} no contact"
    assert contact_words(never, clock) == "out of contact: window closed, no window ahead"


def test_in_contact_with_windows_says_until_when_and_without_windows_nothing():
    clock = MissionClock(lambda: T0)
    assert header_contact(_info(OPEN), clock, 20) == "● until sim 32:00"
    assert header_contact(_info(OPEN), clock, 10) == ""  # the caller's "● online" stands
    assert contact_words(_info(OPEN), clock) == "in contact until sim 32:00"
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
    assert contact_words(_info(wall), clock).endswith("next contact sim 15:00")


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
