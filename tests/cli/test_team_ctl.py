"""`ctl robots add|retire` and `ctl reassign` against a real server and robot
agents (issue 30): a robot under a new name asks to join, is added, takes
over the plan of a retired robot; every step is a separate ctl process."""

from __future__ import annotations

import json
import sys
import time

import pytest

from .helpers import ROBOTS_SCRIPT, Robots, Server, ctl, ids, ok, ok_json, state, until


@pytest.fixture
def server(tmp_path):
    s = Server(tmp_path)
    try:
        yield s
    finally:
        s.stop()


@pytest.fixture
def fleet(server):
    """lru1 (in the mission) and lru3 (not: it asks to join), one process."""
    argv = [sys.executable, str(ROBOTS_SCRIPT), "--connect", server.endpoint]
    r = Robots(server.endpoint, command=[*argv, "lru1:lru_science", "lru3:lru_science"])
    try:
        yield r
    finally:
        r.stop()


def _robots_until(endpoint: str, pred, what: str, timeout: float = 20.0) -> dict:
    deadline = time.monotonic() + timeout
    while True:
        info = ok_json(endpoint, "robots")["robots"]
        if pred(info):
            return info
        assert time.monotonic() < deadline, f"{what} not reached: {info}"
        time.sleep(0.1)


def test_join_retire_and_reassign(server, fleet):
    endpoint = server.endpoint
    info = _robots_until(endpoint, lambda r: r.get("lru3", {}).get("joining"), "lru3 joining")
    assert info["lru3"]["in_mission"] is False and info["lru3"]["type"] == "lru_science"
    said = ok(endpoint, "robots").stdout
    head = "lru3 (lru_science, asks to join: missionctl ctl robots add lru3): "
    assert f"{head}waiting to be added since" in said  # heard: not "offline"

    out = ok(endpoint, "robots", "add", "lru3").stdout
    assert out.startswith("added robot lru3 (lru_science) to the mission at revision"), out
    st = until(endpoint, lambda st: st["robots"]["lru3"]["online"], what="lru3 registered")
    assert st["tasks"]["lru3"] == [] and st["robots"]["lru3"]["joining"] is False

    ok(endpoint, "sync", "lru1", "--through", "lru1-1", "--wait", "20")
    out = ok(endpoint, "robots", "retire", "lru1", "--reason", "wheel stuck").stdout
    assert out.startswith("retired robot lru1 (wheel stuck); its plan to reassign: lru1-1"), out
    assert "note: its plan (lru1-1, lru1-2) awaits reassignment" in out
    # reachable: its queue comes back by its uplink
    until(endpoint, lambda st: st["tasks"]["lru1"][0]["status"] == "idle", what="unsynced")
    r = ctl(endpoint, "sync", "lru1")
    assert r.returncode == 1 and "lru1 is retired (wheel stuck)" in r.stderr, r

    given = ok_json(endpoint, "reassign", "--from", "lru1", "--to", "lru3")
    assert given["value"]["moved"] == ["lru1-1", "lru1-2"] and given["value"]["refused"] == {}
    st = state(endpoint)
    assert ids(st, "lru3") == ["lru1-1", "lru1-2"] and ids(st, "lru1") == []
    assert st["robots"]["lru1"]["retired"] == "wheel stuck"

    ok(endpoint, "undo")
    assert ids(state(endpoint), "lru1") == ["lru1-1", "lru1-2"]
    out = ok(endpoint, "reassign", "lru1-2", "--to", "lru3").stdout
    assert out.startswith("gave lru1-2 to lru3 at revision"), out


def test_unknown_type_and_bad_usage(server):
    r = ctl(server.endpoint, "robots", "add", "rover9", "--type", "hovercraft")
    assert r.returncode == 1, r
    assert "'hovercraft', a type the library 'mars-sample-return' does not have" in r.stderr
    r = ctl(server.endpoint, "robots", "add", "rover9")
    assert r.returncode == 2 and "rover9 has not asked to join" in r.stderr, r
    r = ctl(server.endpoint, "reassign", "--to", "lru2")
    assert r.returncode == 2 and "give skill ids, or --from ROBOT" in r.stderr, r
    r = ctl(server.endpoint, "robots", "retire", "lru2")
    assert r.returncode == 2 and "--reason" in r.stderr, r


def _stale(endpoint: str, *args: str) -> str:
    r = ctl(endpoint, "--json", *args)
    assert r.returncode == 1, r
    obj = json.loads(r.stdout)
    assert obj["ok"] is False and obj["code"] == "stale", obj
    return str(obj["message"])


def test_expect_revision_refuses_stale_team_operations(server):
    endpoint = server.endpoint
    seen = str(state(endpoint)["revision"])
    ok(endpoint, "robots", "add", "lru3", "--type", "lru_science", "--expect-revision", seen)
    seen = str(state(endpoint)["revision"])
    ok(endpoint, "edit", "lru1-2", "--label", "look again")  # someone else's change
    said = _stale(endpoint, "reassign", "lru1-2", "--to", "lru3", "--expect-revision", seen)
    assert "lru1-2" in said and f"after the revision {seen} you saw" in said
    ok(endpoint, "add", "lru1", "recharge")
    for args in (("reassign", "--from", "lru1", "--to", "lru3"), ("robots", "retire", "lru1")):
        extra = ("--reason", "broken") if args[0] == "robots" else ()
        assert "the list of lru1" in _stale(endpoint, *args, *extra, "--expect-revision", seen)
    st = state(endpoint)
    assert ids(st, "lru3") == [] and st["robots"]["lru1"]["retired"] in (None, "")
    fresh = str(st["revision"])
    ok(endpoint, "reassign", "--from", "lru1", "--to", "lru3", "--expect-revision", fresh)
    assert ids(state(endpoint), "lru1") == []


def test_suggest_ranks_robots_by_the_forecast(server):
    endpoint = server.endpoint
    ok(endpoint, "robots", "add", "lru3", "--type", "lru_science")
    hint = ok_json(endpoint, "suggest", "lru1-1", "lru1-2")
    rows = {r["robot"]: r for r in hint["robots"]}
    assert hint["robots"][0]["robot"] == "lru3" and rows["lru3"]["capable"] is True
    assert rows["lru3"]["end_in_s"] is not None and rows["lru3"]["battery_end"] is not None
    assert rows["lru3"]["out_of_coverage_s"] is None  # no simulator: no site map, unknown
    assert "has no skill 'take_science_image'" in rows["lru2"]["refused"]["lru1-2"]
    text = ok(endpoint, "suggest", "take_science_image").stdout.splitlines()
    assert text[0] == (
        "who can take take_science_image (the most taken, then the earliest end, "
        "the least out of coverage, the most battery):"
    )
    assert text[-1].startswith("  3. lru2 cannot: lru2 (lru_manipulator) has no skill"), text
    r = ctl(endpoint, "suggest", "nope-1")
    assert r.returncode == 2 and "no skill with id or library name nope-1" in r.stderr, r


def test_suggest_text_says_the_time_out_of_coverage():
    from backend.cli.ctl.suggest import hint_text

    row = {
        "robot": "lru3",
        "moved": ["lru1-4"],
        "refused": {},
        "end_in_s": 750.0,
        "battery_end": 0.62,
        "battery_assumed": False,
        "out_of_coverage_s": 190.0,
    }
    assert hint_text(row) == "lru3: ends in 12m30s, battery 62% left, 3m10s out of coverage"
    assert hint_text({**row, "out_of_coverage_s": 0.0}).endswith(", in coverage throughout")
    assert hint_text({**row, "out_of_coverage_s": None}).endswith("battery 62% left")
    partial = hint_text({**row, "refused": {"lru1-5": "lru3 has no skill 'x'"}})
    assert partial.startswith("lru3: takes 1 of 2, ends in 12m30s")
    # the row that takes them all says so: why it ranks first (seen in the demo walk)
    whole = hint_text({**row, "moved": ["lru1-3", "lru1-4", "lru1-5"]})
    assert whole.startswith("lru3: takes all 3, ends in 12m30s")
