"""ctl's text in mission time: the simulator's clock when one runs, the wall's otherwise
(BRIEF "One mission clock"); --json stays in wall stamps and seconds."""

from __future__ import annotations

import json
import re
from datetime import UTC, datetime, timedelta

import pytest

from backend.cli.ctl.clock import WALL, CtlClock
from backend.cli.ctl.nowcast import nowcast_line
from backend.cli.ctl.render import pending_text, robots_text, state_json, state_text
from backend.cli.ctl.session import _answer_line
from backend.files.missions import load_mission
from backend.protocol import mapfeed as mf

from .helpers import TUTORIAL, Robots, Server, ok, ok_json, until
from .test_parsing import _fake_client


@pytest.fixture(scope="module")
def tutorial():
    return load_mission(TUTORIAL)


def _status(sim_time: float, speed: float, delay: float = 0.0) -> mf.SimStatus:
    return mf.SimStatus(
        world="w", seed=1, speed=speed, sim_time=sim_time, score=0.0, link_delay_s=delay
    )


def _sim_clock(speed: float = 60.0) -> CtlClock:
    """The sim said 1:00:00 now, at `speed`."""
    return CtlClock.of_status(_status(3600.0, speed), datetime.now(UTC))


def _online_since(client, since: datetime) -> None:
    client.robots["lru1"] = client.robots["lru1"].model_copy(update={"since": since})


def test_the_clock_turns_wall_stamps_and_durations_into_sim_time():
    clock = _sim_clock(60.0)
    assert clock.simulated and clock.speed == 60.0
    assert clock.stamp(clock.wall - timedelta(seconds=30)) == "sim 0:30:00"
    assert clock.stamp(clock.wall + timedelta(seconds=10)) == "sim 1:10:00"
    assert clock.duration(10.0) == "10 min" and clock.fine(10.0) == "10 min"
    assert clock.age(clock.wall - timedelta(seconds=2), clock.wall) == "2 min"
    # a stamp from before this sim run started: the wall's, never a made-up sim time
    before = clock.wall - timedelta(seconds=61)
    assert clock.sim_stamp(before) is None and clock.stamp(before) == WALL.stamp(before)
    assert re.fullmatch(r"\d\d:\d\d:\d\d", WALL.stamp(before))
    # no sim, or one that stands still: the wall's clock, as ctl always said it
    assert CtlClock.of_status(None) is WALL and CtlClock.of_status(_status(5.0, 0.0)) is WALL
    assert not WALL.simulated and WALL.fine(10.0) == "10.0 s" and WALL.duration(10.0) == "10 s"


def test_state_says_delay_ages_and_stamps_in_sim_time(tutorial):
    client = _fake_client(tutorial)  # lru1: delay 2 s, heard 3 s ago; a sync sent 12 s ago
    clock = _sim_clock(60.0)
    _online_since(client, clock.wall - timedelta(seconds=30))
    text = state_text(client, clock=clock)
    assert "lru1 (lru_science) — online since sim 0:30:00; delay 2 min, heard 3 min ago" in text
    assert "(uplinking: command 1, sent 12 min ago)" in text
    assert "pending: command 1 to lru2 (seq 1): sync lru2-1, lru2-2: sent 12 min ago" in text
    assert "[expires sim " in text
    assert " s ago" not in text and "2.0 s" not in text  # no wall duration left


def test_without_a_sim_the_text_is_the_walls_as_before(tutorial):
    client = _fake_client(tutorial)
    _online_since(client, datetime.now(UTC) - timedelta(seconds=30))
    text = state_text(client)
    assert text == state_text(client, clock=WALL)
    assert re.search(r"lru1 \(lru_science\) — online since \d\d:\d\d:\d\d; delay 2\.0 s, ", text)
    assert "heard 3 s ago" in text and "sent 12 s ago" in text and "sim " not in text


def test_robots_and_pending_say_ages_in_sim_time(tutorial):
    client = _fake_client(tutorial)
    clock = _sim_clock(10.0)
    robots = robots_text(client, clock)
    assert "delay 20 s, heard 30 s ago" in robots
    assert "sync lru2-1, lru2-2: sent 2 min ago" in robots and "[expires sim " in robots
    pending = pending_text(client, clock=clock)
    assert "sent 2 min ago" in pending and "sent 12 s ago" in pending_text(client)


def test_json_stays_in_wall_stamps_and_seconds(tutorial):
    client = _fake_client(tutorial)
    data = state_json(client)
    link = data["robots"]["lru1"]["link"]
    assert link["delay_s"] == 2.0 and 2 < link["heard_age_s"] < 10
    assert "sim " not in json.dumps(data)


def test_nowcast_and_answers_say_durations_in_sim_time():
    nc = {"skill": None, "held": "", "x": None, "y": None, "battery": None, "age_s": 10.0}
    assert nowcast_line("lru1", nc, _sim_clock(60.0)).endswith("(from a report 10 min old)")
    assert nowcast_line("lru1", nc).endswith("(from a report 10 s old)")

    class Answered:
        id, robot, done, kept, reason = 3, "lru1", [], [], ""
        state = type("S", (), {"value": "acked"})()
        created = datetime(2030, 1, 1, tzinfo=UTC)
        settled = created + timedelta(seconds=12)

    assert _answer_line(Answered(), _sim_clock(10.0)) == "command 3 applied by lru1 after 2 min"
    assert _answer_line(Answered()) == "command 3 applied by lru1 after 12.0 s"


# ---------------------------------------------------------------- live: a server, a sim's status


@pytest.fixture
def live(tmp_path):
    """A server, its robots, and (`sim(speed)`) a simulator's status at a given speed."""
    from backend.transport import client_config, close_session, open_session, serve

    s = Server(tmp_path)
    robots = None
    sessions: list = []
    keep: list = []

    def sim(speed: float) -> None:
        session = open_session(client_config([s.endpoint]))
        sessions.append(session)
        status = _status(3600.0, speed, delay=600.0)
        keep.append(serve(session, mf.KEY_STATUS, lambda _p: mf.dump(status)))

    try:
        robots = Robots(s.endpoint, "lru1:lru_science", "lru2:lru_manipulator")
        until(s.endpoint, lambda st: st["robots"]["lru1"]["online"], what="lru1 online")
        yield s.endpoint, sim
    finally:
        keep.clear()
        for session in sessions:
            close_session(session)
        if robots is not None:
            robots.stop()
        s.stop()


def test_ctl_state_is_in_sim_time_while_a_sim_runs(live):
    endpoint, sim = live
    wall = ok(endpoint, "state", "lru1").stdout
    assert re.search(r"lru1 \(lru_science\) — online since \d\d:\d\d:\d\d", wall), wall
    assert "sim " not in wall
    sim(10.0)
    text = ok(endpoint, "state", "lru1").stdout
    head = text.splitlines()[1]
    assert re.match(r"lru1 \(lru_science\) — online since sim 0:\d\d:\d\d\b", head), head
    # the delay and the age in mission time: whole sim seconds or minutes, never "0.0 s"
    assert re.search(r"delay \d+ (s|min)(,|$)", head) and "heard " in head, head
    data = ok_json(endpoint, "state", "lru1")  # JSON: wall stamps, as ever
    assert datetime.fromisoformat(data["robots"]["lru1"]["since"]).tzinfo is not None
    assert "sim " not in json.dumps(data["robots"])
