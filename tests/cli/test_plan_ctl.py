"""`ctl check`, `ctl waive` / `unwaive` and `ctl timeline` against a real
server (the tutorial mission; no simulator: no map, no telemetry)."""

from __future__ import annotations

import json

import pytest

from .helpers import Server, ctl, ok, ok_json

DEADLOCK = "barrier.deadlock:b1+b2"


@pytest.fixture
def endpoint(tmp_path):
    s = Server(tmp_path)
    try:
        yield s.endpoint
    finally:
        s.stop()


def test_check_waive_and_timeline_of_a_deadlocked_plan(endpoint):
    # lru1: lru1-1 then lru1-2; lru2: lru2-1 then lru2-2 -- crossed barriers
    ok(endpoint, "barrier", "lru1-1", "lru2-2")
    ok(endpoint, "barrier", "lru1-2", "lru2-1")

    r = ctl(endpoint, "check")
    assert r.returncode == 1, r.stderr
    assert DEADLOCK in r.stdout and "1 error(s) (0 waived)" in r.stdout
    assert "no site map" in r.stdout  # said what it could not check

    r = ctl(endpoint, "check", "lru2", "--json")
    assert r.returncode == 1
    out = json.loads(r.stdout)
    assert out["ok"] is False and out["errors"] == 1
    (f,) = [f for f in out["findings"] if f["rule"] == "barrier.deadlock"]
    assert f["id"] == DEADLOCK and f["severity"] == "error" and f["waiver"] is None

    r = ctl(endpoint, "sync", "lru1")
    assert r.returncode == 1 and DEADLOCK in r.stderr and "ctl waive" in r.stderr

    tl = ok_json(endpoint, "timeline")
    assert tl["end"] is None and tl["summary"].startswith("plan never ends")

    done = ok_json(endpoint, "waive", DEADLOCK, "--reason", "released by hand")
    assert done["ok"] and done["value"] == {"check": DEADLOCK}
    r = ok(endpoint, "check")
    assert "waived at revision" in r.stdout and "released by hand" in r.stdout
    assert ok_json(endpoint, "state")["waivers"][DEADLOCK]["reason"] == "released by hand"

    ok(endpoint, "unwaive", DEADLOCK)
    assert ctl(endpoint, "check").returncode == 1

    ok(endpoint, "unbarrier", "b2")
    assert ctl(endpoint, "check", "--json").returncode == 0
    tl = ok_json(endpoint, "timeline")
    assert tl["end"] is not None and tl["summary"].startswith("plan ends")
    lru1 = tl["robots"]["lru1"]["skills"]
    assert [s["id"] for s in lru1] == ["lru1-1", "lru1-2"]
    assert lru1[0]["end"] <= lru1[1]["start"]
    text = ok(endpoint, "timeline").stdout
    assert "plan ends" in text and "lru1-2" in text


def test_waive_refuses_bad_ids_before_sending(endpoint):
    r = ctl(endpoint, "waive", "not an id", "--reason", "x")
    assert r.returncode == 2 and "check" in r.stderr
    r = ctl(endpoint, "waive", "barrier.nonsense:b1", "--reason", "x")
    assert r.returncode == 1 and "no plan check 'barrier.nonsense'" in r.stderr
