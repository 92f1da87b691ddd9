"""Why a queued command expired before it was sent, as its refusal says; its
stamps on the mission clock (the sim's while one runs)."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import backend.server.contact as contact
from backend.protocol.mapfeed import SimStatus
from backend.protocol.messages import RobotInfo
from backend.server.contact import ContactWatch
from backend.server.robots import _why_unsent

WALL = ContactWatch().time_text  # no simulator: the wall's clock


def test_an_online_robot_was_out_of_reach_an_offline_one_offline_since_when():
    since = datetime(2030, 7, 1, 8, 4, 5)
    online = RobotInfo(name="lru1", online=True)
    assert _why_unsent("lru1", online, WALL) == "it was out of reach"
    assert _why_unsent("lru1", RobotInfo(name="lru1", since=since), WALL) == (
        "lru1 was offline since 08:04:05"
    )
    assert _why_unsent("lru1", RobotInfo(name="lru1"), WALL) == "lru1 was offline"
    assert _why_unsent("lru9", None, WALL) == "lru9 was offline"


def test_while_a_sim_runs_a_past_stamp_is_said_in_sim_time(monkeypatch):
    heard = datetime(2030, 7, 1, 8, 10, 0, tzinfo=UTC)
    monkeypatch.setattr(contact, "_now", lambda: heard)
    watch = ContactWatch()
    watch.mirror.apply_full(
        SimStatus(world="w", seed=1, speed=10.0, link_delay_s=0, sim_time=3600, score=0)
    )
    watch._changed()  # the status heard at `heard`: sim 1:00:00
    # a minute of wall before it, at ten times: ten sim-minutes before
    since = heard - timedelta(minutes=1)
    assert _why_unsent("lru1", RobotInfo(name="lru1", since=since), watch.time_text) == (
        "lru1 was offline since sim 0:50:00"
    )
    assert watch.time_text(heard + timedelta(seconds=6)) == "sim 1:01:00"
