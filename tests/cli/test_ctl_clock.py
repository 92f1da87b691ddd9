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

from .helpers import TUTORIAL, Robots, Server, ctl, ok, ok_json, until
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


# ---------------------------------------------------------------- watch, queued, plan views


def test_watch_says_a_robots_stamps_in_sim_time():
    from backend.cli.ctl.render import watch_line
    from backend.protocol.messages import RobotInfo

    clock = _sim_clock(60.0)
    info = RobotInfo(name="lru1", online=True, since=clock.wall - timedelta(seconds=30))
    assert watch_line("fleet", info, False, clock) == "robot lru1 online since sim 0:30:00"
    wall = watch_line("fleet", info, False)
    assert wall is not None and re.fullmatch(r"robot lru1 online since \d\d:\d\d:\d\d", wall)
    data = json.loads(watch_line("fleet", info, True, clock) or "")  # JSON: the wall's ISO stamp
    assert datetime.fromisoformat(data["robot"]["since"]) == info.since


def test_a_queued_command_says_its_expiry_in_sim_time():
    from types import SimpleNamespace

    from backend.cli.ctl.render import describe

    clock = _sim_clock(60.0)
    expires = clock.wall + timedelta(seconds=10)  # 10 wall s: 10 sim minutes on
    value = {"robot": "lru1", "command": 4, "skills": ["lru1-1"], "expires": expires.isoformat()}
    op = SimpleNamespace(op="sync")
    reply = SimpleNamespace(value=value, revision=7, duplicate=False)
    said = describe(op, reply, 6, None, clock)
    assert said == "queued for lru1, command 4: sync lru1-1 (expires sim 1:10:00) at revision 7"
    wall = describe(op, reply, 6, None)
    assert re.search(r"\(expires \d\d:\d\d:\d\d\) at revision 7$", wall) and "sim " not in wall


def _waiting_plan(speed: float):
    """r1 drives 100 m (100 robot s), then meets r2 at barrier b1: r2 waits for it."""
    from backend.core.plan.forecast import forecast
    from backend.core.plan.inputs import PlanInputs, RobotNow
    from tests.core.plan.helpers import LIBRARY, T0, mission, pose, skill

    tasks = {
        "r1": [skill("r1-1", "drive", goal=pose(100, 0)), skill("r1-2", "meet")],
        "r2": [skill("r2-1", "meet")],
    }
    m = mission({"r1": "rover", "r2": "rover"}, tasks, {"b1": ["r1-2", "r2-1"]})
    robots = {r: RobotNow(at=T0, x=0.0, y=0.0, battery=1.0) for r in m.robots}
    fc = forecast(m, LIBRARY, PlanInputs(now=T0, robots=robots, speed=speed))
    wall = datetime.fromtimestamp(T0, UTC)  # the sim said 1:00:00 then
    return fc, m, CtlClock(speed, 3600.0, wall)


def test_timeline_says_times_and_waits_in_sim_time():
    from backend.cli.ctl.plan import timeline_json, timeline_text

    fc, m, clock = _waiting_plan(speed=10.0)  # the drive: 10 wall s, 100 sim s
    lines = timeline_text(fc, m, clock).splitlines()
    assert lines[0] == "now sim 1:00:00 · plan ends sim 1:02:30 · critical: r2", lines
    r1 = next(ln for ln in lines if ln.startswith("  r1-1"))
    assert "sim 1:00:00 - sim 1:01:40" in r1, r1
    r2 = next(ln for ln in lines if ln.startswith("  r2-1"))
    # the wait: 10 wall s, i.e. 1:40 on the sim's clock
    assert "waits 1:40 at b1" in r2 and "sim 1:01:40 - sim 1:02:30" in r2, r2
    assert "r1: ends sim 1:02:30, battery 90% at the end" in lines
    assert "sim " not in json.dumps(timeline_json(fc, m))  # JSON: ISO wall stamps, as ever
    fc, m, _ = _waiting_plan(speed=1.0)  # no sim: the wall's clock and seconds
    text = timeline_text(fc, m)
    assert re.match(r"now \d\d:\d\d:\d\d · plan ends \d\d:\d\d:\d\d", text), text
    assert "waits 1:40 at b1" in text and "sim " not in text


def test_check_says_the_link_delay_in_sim_time():
    from backend.cli.ctl.plan import _inputs_text
    from backend.core.plan.inputs import LinkModel, PlanInputs

    inputs = PlanInputs(now=0.0, link=LinkModel(one_way_s=10.0))  # 600 sim s at speed 60
    assert _inputs_text(inputs, _sim_clock(60.0)).endswith("; link delay 10 min")
    assert _inputs_text(inputs).endswith("; link delay 10 s")


def test_suggest_says_ends_and_coverage_in_sim_time():
    from backend.cli.ctl.suggest import hint_text

    row = {
        "robot": "lru3",
        "moved": ["lru1-4"],
        "refused": {},
        "end_in_s": 75.0,  # wall seconds: 12m30s at speed 10
        "battery_end": 0.62,
        "battery_assumed": False,
        "out_of_coverage_s": 19.0,
    }
    said = "lru3: ends in 12m30s, battery 62% left, 3m10s out of coverage"
    assert hint_text(row, _sim_clock(10.0)) == said
    assert hint_text(row) == "lru3: ends in 1m15s, battery 62% left, 19s out of coverage"


def test_ctl_queued_timeline_and_check_are_in_sim_time_while_a_sim_runs(live):
    endpoint, sim = live
    wall = ok(endpoint, "sync", "lru1", "--expire", "10m").stdout
    assert re.search(r"\(expires \d\d:\d\d:\d\d\) at revision", wall) and "sim " not in wall, wall
    sim(10.0)
    said = ok(endpoint, "unsync", "lru1", "--expire", "10m").stdout
    assert re.search(r"\(expires sim \d+:\d\d:\d\d\) at revision", said), said
    timeline = ok(endpoint, "timeline").stdout
    assert timeline.startswith("now sim 1:00:"), timeline
    checked = ctl(endpoint, "check").stdout  # the sim's 600 s delay, not its 60 wall seconds
    assert checked.rstrip().endswith("; link delay 10 min"), checked
