"""Why a queued command expired before it was sent, as its refusal says."""

from __future__ import annotations

from datetime import datetime

from backend.protocol.messages import RobotInfo
from backend.server.robots import _why_unsent


def test_an_online_robot_was_out_of_reach_an_offline_one_offline_since_when():
    since = datetime(2030, 7, 1, 8, 4, 5)
    assert _why_unsent("lru1", RobotInfo(name="lru1", online=True)) == "it was out of reach"
    assert _why_unsent("lru1", RobotInfo(name="lru1", since=since)) == (
        "lru1 was offline since 08:04:05"
    )
    assert _why_unsent("lru1", RobotInfo(name="lru1")) == "lru1 was offline"
    assert _why_unsent("lru9", None) == "lru9 was offline"
