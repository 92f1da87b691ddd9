"""A command that reaches the robot past its expiry is answered `expired`, with
why on the mission clock: the simulator's when it sets the agent's
(`mission_time`, `time_scale`), else the wall's as ever (BRIEF "One mission clock")."""

from __future__ import annotations

import re
from datetime import UTC, datetime, timedelta

from backend.agent.uplink import CommandLog, expired_reason
from backend.core.model import Dequeue
from backend.protocol.messages import UplinkEntry


def _expired(log: CommandLog, late_s: float) -> str:
    """The reason of the answer to a command whose expiry passed `late_s` ago."""
    expires = datetime.now(UTC) - timedelta(seconds=late_s)
    entry = UplinkEntry(seq=1, id=1, expires=expires, command=Dequeue(ids=["lru1-1"]))

    def dispatch(_command: object):
        raise AssertionError("an expired command is never applied")

    answer = log.process(entry, dispatch, lambda: 1)
    assert answer.outcome == "expired"
    return answer.reason


def test_an_expired_command_says_when_on_the_sims_clock():
    # the sim says 1:02:00 at 60 sim s per wall s: 2 wall s late are 2 sim minutes
    arrived = datetime(2030, 1, 1, 6, 7, 40, tzinfo=UTC)
    expires = arrived - timedelta(seconds=2)
    said = expired_reason(arrived, expires, 3720.0, 60.0)
    assert said == "it arrived at sim 1:02:00, after its expiry sim 1:00:00"
    # the robot's log reads the agent's clock when the command arrives
    log = CommandLog("lru1", mission_time=lambda: 3720.0, time_scale=lambda: 60.0)
    assert _expired(log, 2.0).startswith("it arrived at sim 1:02:00, after its expiry sim ")


def test_without_a_sim_it_says_the_walls_utc_time_as_before():
    arrived = datetime(2030, 1, 1, 6, 7, 40, tzinfo=UTC)
    said = expired_reason(arrived, arrived - timedelta(seconds=10), arrived.timestamp())
    assert said == "it arrived at 06:07:40, after its expiry 06:07:30 UTC"
    reason = _expired(CommandLog("lru1"), 2.0)  # the agent's default clock: POSIX time
    assert re.fullmatch(
        r"it arrived at \d\d:\d\d:\d\d, after its expiry \d\d:\d\d:\d\d UTC", reason
    ), reason
