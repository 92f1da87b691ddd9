"""`missionctl ctl` against a real `missionctl server` subprocess (and, for
the robot operations, the robot agents of docs/examples/trivial_robots.py).

Every step is a separate ctl process, as a script would run it."""

from __future__ import annotations

import json
import re
import selectors
import subprocess
import sys
import time

import pytest
import yaml

from backend.files.missions import load_mission

from .helpers import (
    CTL_CMD,
    LIBRARY,
    ROBOTS_SCRIPT,
    ROOT,
    Robots,
    Server,
    ctl,
    env,
    ids,
    ok,
    ok_json,
    skill,
    state,
    until,
)


@pytest.fixture
def server(tmp_path):
    s = Server(tmp_path)
    try:
        yield s
    finally:
        s.stop()


@pytest.fixture
def endpoint(server):
    return server.endpoint


def refused(endpoint: str, *args: str, **kw) -> subprocess.CompletedProcess:
    r = ctl(endpoint, *args, **kw)
    assert r.returncode == 1, (
        f"ctl {' '.join(args)} -> {r.returncode}\nstdout: {r.stdout}\nstderr: {r.stderr}"
    )
    assert r.stderr.startswith("missionctl: refused: "), r.stderr
    assert "Traceback" not in r.stderr
    return r


# ---------------------------------------------------------------- state


def test_state_json_structure(endpoint):
    st = state(endpoint)
    assert {"revision", "name", "library", "robots", "tasks", "barriers", "markers"} <= set(st)
    assert st["name"] == "Tutorial" and isinstance(st["revision"], int)
    assert set(st["robots"]) == {"lru1", "lru2"}
    lru1 = st["robots"]["lru1"]
    assert lru1["type"] == "lru_science" and lru1["online"] is False and lru1["manifest"] is None
    assert {"since", "kind", "in_mission"} <= set(lru1)
    assert ids(st, "lru1") == ["lru1-1", "lru1-2"] and ids(st, "lru2") == ["lru2-1", "lru2-2"]
    s = st["tasks"]["lru1"][0]
    assert {
        "id",
        "skill",
        "label",
        "status",
        "status_info",
        "attempt",
        "params",
        "bindings",
    } <= set(s)
    assert (s["skill"], s["label"], s["status"], s["attempt"]) == (
        "drive_to",
        "drive to POI-A",
        "idle",
        1,
    )
    assert s["bindings"] == {"goal": "POI-A"}
    assert s["params"]["goal"] == {
        "x": 10.0,
        "y": 5.0,
        "z": 0.0,
        "roll": 0.0,
        "pitch": 0.0,
        "yaw": 0.0,
    }
    assert s["params"]["speed"] == 0.5  # the library default, filled in
    assert st["barriers"] == {}
    assert st["markers"]["POI-A"]["kind"] == "pose" and st["markers"]["POI-A"]["pose"]["x"] == 10.0

    text = ok(endpoint, "state").stdout
    assert f"revision {st['revision']}" in text
    for needle in (
        "lru1 (lru_science)",
        "lru1-1",
        "drive to POI-A",
        "drive_to",
        "goal=@POI-A",
        "lru2-1",
        "goal=(9,4)",
        "POI-A",
        "barriers: none",
    ):
        assert needle in text, needle
    only = ok_json(endpoint, "state", "lru2")
    assert set(only["tasks"]) == {"lru2"}
    r = ctl(endpoint, "state", "lru9")
    assert r.returncode == 2 and "lru9" in r.stderr


# ---------------------------------------------------------------- editing the plan


def test_add_edit_move_delete_barrier_undo_redo(endpoint):
    r = ok_json(
        endpoint,
        "add",
        "lru1",
        "drive_to",
        "--param",
        "goal={x: 3, y: 4, yaw: 0.5rad}",
        "--label",
        "drive out",
        "--param",
        "speed=0.4",
    )
    assert r["ok"] is True and r["op"] == "add" and r["notes"] == []
    a = r["value"]["id"]
    st = state(endpoint)
    assert st["revision"] == r["revision"]
    s = skill(st, a)
    assert (s["skill"], s["label"], s["status"]) == ("drive_to", "drive out", "idle")
    assert s["params"]["goal"] == {
        "x": 3.0,
        "y": 4.0,
        "z": 0.0,
        "roll": 0.0,
        "pitch": 0.0,
        "yaw": 0.5,
    }
    assert s["params"]["speed"] == 0.4 and s["bindings"] == {}
    assert ids(st, "lru1")[-1] == a

    # human output: one line naming id, skill, robot and revision
    out = ok(endpoint, "add", "lru1", "drive_to", "--param", "goal=@POI-A", "--at", "0").stdout
    m = re.fullmatch(r"added (lru1-\d+) \(drive_to\) to lru1 at revision (\d+)\n", out)
    assert m, out
    b = m.group(1)
    st = state(endpoint)
    assert ids(st, "lru1")[0] == b and skill(st, b)["bindings"] == {"goal": "POI-A"}
    assert skill(st, b)["params"]["goal"]["x"] == 10.0

    # edit: label, value, policies (unnamed ones are kept)
    ok(
        endpoint,
        "edit",
        a,
        "--label",
        "drive further",
        "--param",
        "goal={x: 6, y: 8}",
        "--retries",
        "2",
    )
    ok(endpoint, "edit", a, "--recharge-below", "0.25")
    s = skill(state(endpoint), a)
    assert s["label"] == "drive further" and s["params"]["goal"]["x"] == 6.0
    assert s["policies"] == {"retries": 2, "pause_out_of_comms": False, "recharge_below": 0.25}
    # bind, then unbind (the value stays)
    ok(endpoint, "edit", a, "--param", "goal=@POI-A")
    assert skill(state(endpoint), a)["bindings"] == {"goal": "POI-A"}
    ok(endpoint, "edit", a, "--unbind", "goal")
    s = skill(state(endpoint), a)
    assert s["bindings"] == {} and s["params"]["goal"]["x"] == 10.0
    # an edit that changes nothing says so
    out = ok(endpoint, "edit", a, "--label", "drive further").stdout
    assert "nothing changed" in out

    # move within the unsynchronized section
    assert ids(state(endpoint), "lru1") == [b, "lru1-1", "lru1-2", a]
    out = ok(endpoint, "move", a, "1").stdout
    assert out.startswith(f"moved {a} to position 1 of lru1's unsynchronized section at revision")
    assert ids(state(endpoint), "lru1") == [b, a, "lru1-1", "lru1-2"]

    # barrier / unbarrier
    r = ok_json(endpoint, "barrier", a, "lru2-2")
    bid = r["value"]["barrier"]
    st = state(endpoint)
    assert st["barriers"] == {bid: [a, "lru2-2"]}
    assert skill(st, a)["barrier"] == bid
    assert f"{a} [{bid}]" in ok(endpoint, "state").stdout
    refused(endpoint, "barrier", "lru1-1", "lru1-2")  # one robot
    ok(endpoint, "unbarrier", bid)
    assert state(endpoint)["barriers"] == {}

    # undo / redo: the same client id undoes its own edits, another cannot
    out = ok(endpoint, "undo").stdout
    assert out.startswith("undid unbarrier at revision")
    assert state(endpoint)["barriers"] == {bid: [a, "lru2-2"]}
    r = refused(endpoint, "undo", client_id="someone-else")
    assert "nothing to undo" in r.stderr
    out = ok(endpoint, "redo").stdout
    assert out.startswith("redid unbarrier")
    assert state(endpoint)["barriers"] == {}

    # delete and undo: back in place
    ok(endpoint, "delete", a, b)
    assert ids(state(endpoint), "lru1") == ["lru1-1", "lru1-2"]
    ok(endpoint, "undo")
    assert ids(state(endpoint), "lru1") == [b, a, "lru1-1", "lru1-2"]


def test_expect_revision_refuses_stale_edits(endpoint):
    seen = state(endpoint)["revision"]
    ok(endpoint, "edit", "lru1-1", "--label", "first", "--expect-revision", str(seen))
    r = ctl(
        endpoint, "--json", "edit", "lru1-1", "--label", "second", "--expect-revision", str(seen)
    )
    assert r.returncode == 1
    obj = json.loads(r.stdout)
    assert obj["ok"] is False and obj["code"] == "stale" and "lru1-1" in obj["message"]
    assert obj["message"] in r.stderr
    assert skill(state(endpoint), "lru1-1")["label"] == "first"


def test_request_id_applies_once(endpoint):
    r1 = ok_json(endpoint, "add", "lru2", "recharge", "--request-id", "retry-me-1")
    r2 = ok_json(endpoint, "add", "lru2", "recharge", "--request-id", "retry-me-1")
    assert (
        r2["duplicate"] is True and r2["value"] == r1["value"] and r2["revision"] == r1["revision"]
    )
    assert [s["skill"] for s in state(endpoint)["tasks"]["lru2"]].count("recharge") == 1
    # without --request-id every invocation is a new request, even with the same client id
    ok(endpoint, "add", "lru2", "recharge")
    assert [s["skill"] for s in state(endpoint)["tasks"]["lru2"]].count("recharge") == 2


def test_a_distant_robot_never_slows_ctl_and_wait_waits_for_its_answer(endpoint):
    """A robot 3 s away: the operation returns at once (exit 0, "queued"),
    --wait waits for the robot's answer, a --wait too short exits 3 with the
    command still pending (listed by `ctl pending`)."""
    slow = Robots(
        endpoint,
        "lru1:lru_science",
        command=[
            sys.executable,
            str(ROBOTS_SCRIPT),
            "--connect",
            endpoint,
            "--delay",
            "3",
            "lru1:lru_science",
        ],
    )
    try:
        until(endpoint, lambda st: st["robots"]["lru1"]["online"], what="lru1 online")
        t0 = time.monotonic()
        out = ok(endpoint, "sync", "lru1", "--through", "lru1-1", "--timeout", "2").stdout
        assert time.monotonic() - t0 < 5  # a ctl process, not the robot's 6 s round trip
        assert out.startswith("queued for lru1, command 1: sync lru1-1 at revision"), out
        r = ctl(endpoint, "--json", "sync", "lru1", "--wait", "1")
        assert r.returncode == 3, r
        obj = json.loads(r.stdout)
        assert obj["ok"] is False and obj["code"] == "pending"
        assert obj["value"]["command"] == 2 and obj["answers"][0]["id"] == 2
        assert "stays pending" in r.stderr and "ctl cancel" in r.stderr
        listed = ok(endpoint, "pending").stdout
        assert "command 2 to lru1 (seq 2): sync lru1-2" in listed, listed
        r = ok(endpoint, "run", "lru1", "--wait", "20")
        lines = r.stdout.splitlines()
        assert lines[0].startswith("queued for lru1, command 3: run"), lines
        assert re.match(r"command 3 applied by lru1 after [0-9.]+ s", lines[1]), lines
        st = until(endpoint, lambda st: statuses(st, "lru1") == ["success", "success"], what="run")
        assert st["uplink"]["lru1"][0]["state"] == "acked"
        assert st["robots"]["lru1"]["link"]["delay_s"] >= 2.5  # the robot's 3 s, estimated
        assert ok(endpoint, "pending").stdout.strip() == "no pending commands"
    finally:
        slow.stop()


# ---------------------------------------------------------------- markers


def test_markers_and_bindings(endpoint):
    ok(
        endpoint,
        "marker",
        "add",
        "ROI-1",
        "--area",
        "0,0 6,0 6,6 0,6",
        "--description",
        "sampling region",
    )
    ok(endpoint, "marker", "add", "P1", "--pose", "1,1,0,0,0,1.5rad")
    out = ok(endpoint, "marker", "add", "W1", "--position=-2,3").stdout
    assert out.startswith("added marker W1 (position) at revision")
    st = state(endpoint)
    assert st["markers"]["ROI-1"]["kind"] == "area" and len(st["markers"]["ROI-1"]["area"]) == 4
    assert st["markers"]["ROI-1"]["description"] == "sampling region"
    assert st["markers"]["W1"]["position"] == {"x": -2.0, "y": 3.0, "z": 0.0}

    # @MARKER: a position parameter is bound, a marker parameter names the marker
    p = ok_json(
        endpoint,
        "add",
        "lru2",
        "pick_stone",
        "--param",
        "target=@POI-A",
        "--param",
        "region=@ROI-1",
    )["value"]["id"]
    s = skill(state(endpoint), p)
    assert s["bindings"] == {"target": "POI-A"} and s["params"]["region"] == "ROI-1"
    assert s["params"]["target"] == {"x": 10.0, "y": 5.0, "z": 0.0}
    r = refused(
        endpoint,
        "add",
        "lru2",
        "pick_stone",
        "--param",
        "target=@POI-A",
        "--param",
        "region=@POI-A",
    )
    assert "region" in r.stderr and "area" in r.stderr

    # moving a marker moves the idle skills bound to it
    ok(endpoint, "marker", "move", "POI-A", "--pose", "12,7")
    st = state(endpoint)
    assert skill(st, "lru1-1")["params"]["goal"]["x"] == 12.0
    assert skill(st, p)["params"]["target"] == {"x": 12.0, "y": 7.0, "z": 0.0}
    # --position on a pose marker keeps its orientation
    ok(endpoint, "marker", "move", "P1", "--position", "2,2")
    assert state(endpoint)["markers"]["P1"]["pose"] == {
        "x": 2.0,
        "y": 2.0,
        "z": 0.0,
        "roll": 0.0,
        "pitch": 0.0,
        "yaw": 1.5,
    }
    r = refused(endpoint, "marker", "move", "ROI-1", "--position", "1,1")
    assert "ROI-1" in r.stderr and "area" in r.stderr

    # rename: bindings follow
    ok(endpoint, "marker", "rename", "POI-A", "POI-B")
    st = state(endpoint)
    assert "POI-A" not in st["markers"] and "POI-B" in st["markers"]
    assert skill(st, "lru1-1")["bindings"] == {"goal": "POI-B"}
    refused(endpoint, "marker", "rename", "P1", "POI-B")  # exists

    # delete: idle skills keep their values, unbound
    ok(endpoint, "marker", "delete", "P1")
    assert "P1" not in state(endpoint)["markers"]
    r = refused(endpoint, "marker", "delete", "P1")
    assert "P1" in r.stderr
    ok(endpoint, "undo")
    assert "P1" in state(endpoint)["markers"]


# ---------------------------------------------------------------- refusals and bad usage


def test_refusals_name_robot_and_skill(endpoint):
    before = state(endpoint)["revision"]
    r = refused(endpoint, "edit", "lru1-1", "--param", "speed=7")
    assert "lru1" in r.stderr and "lru1-1" in r.stderr and "speed" in r.stderr
    r = refused(endpoint, "add", "lru1", "fly_to")
    assert "lru1" in r.stderr and "fly_to" in r.stderr
    r = refused(endpoint, "add", "lru1", "drive_to")
    assert "goal" in r.stderr  # required parameter missing
    r = refused(endpoint, "add", "lru9", "drive_to")
    assert "lru9" in r.stderr
    r = refused(endpoint, "delete", "lru1-99")
    assert "lru1-99" in r.stderr
    r = refused(endpoint, "move", "lru1-1", "5")
    assert "lru1" in r.stderr
    r = refused(endpoint, "retry", "lru1-1")
    assert "lru1-1" in r.stderr and "failed" in r.stderr
    r = refused(endpoint, "run", "--all")
    assert "lru1" in r.stderr and "lru2" in r.stderr
    r = refused(endpoint, "unbarrier", "b42")
    assert "b42" in r.stderr

    # --json: one object on stdout, the sentence on stderr
    r = ctl(endpoint, "--json", "edit", "lru2-1", "--param", "tolerance=99")
    assert r.returncode == 1
    obj = json.loads(r.stdout)
    assert (
        obj["ok"] is False
        and obj["code"] == "bad_param"
        and obj["robot"] == "lru2"
        and obj["param"] == "tolerance"
    )
    assert obj["message"] in r.stderr
    assert state(endpoint)["revision"] == before  # nothing changed


def test_sync_without_robot_agent_is_queued_and_can_be_cancelled(endpoint):
    """Protocol 2: a robot not connected gets its commands when it comes."""
    out = ok(endpoint, "sync", "lru1").stdout
    assert out.startswith("queued for lru1, command 1: sync lru1-1, lru1-2"), out
    st = state(endpoint)
    assert all(s["status"] == "idle" for s in st["tasks"]["lru1"])  # not on the robot
    assert [s["uplink"]["command"] for s in st["tasks"]["lru1"]] == [1, 1]
    text = ok(endpoint, "state", "lru1").stdout
    assert "(uplinking: command 1, queued" in text and "pending: command 1 to lru1" in text
    refused(endpoint, "edit", "lru1-1", "--label", "x")  # uplinking: locked
    out = ok(endpoint, "cancel", "1").stdout
    assert out.startswith("cancelled command 1 to lru1"), out
    r = refused(endpoint, "cancel", "1")
    assert "cancelled already" in r.stderr
    r = ctl(endpoint, "--json", "cancel", "99")
    assert r.returncode == 1 and json.loads(r.stdout)["code"] == "unknown_command"
    ok(endpoint, "edit", "lru1-1", "--label", "editable again")


def test_bad_usage_exits_2_and_sends_nothing(endpoint):
    before = state(endpoint)["revision"]
    for args, needle in [
        (["add", "lru1", "drive_to", "--param", "goal"], "--param"),
        (["add", "lru1", "drive_to", "--param", "goal={x: 3"], "--param goal"),
        (["frobnicate"], "invalid choice"),
        (["move", "lru1-1", "first"], "INDEX"),
        (["marker", "add", "M"], "--pose"),
        (["run"], "ROBOT or --all"),
        (["edit", "lru1-1"], "nothing to change"),
    ]:
        r = ctl(endpoint, *args)
        assert r.returncode == 2, (args, r)
        assert needle in r.stderr, (args, r.stderr)
        assert "Traceback" not in r.stderr
    assert state(endpoint)["revision"] == before


# ---------------------------------------------------------------- files


def test_save_load_round_trip(endpoint, tmp_path):
    ok(
        endpoint,
        "add",
        "lru1",
        "drive_to",
        "--param",
        "goal={x: 1, y: 2, yaw: 0.3rad}",
        "--label",
        "extra",
        "--retries",
        "1",
    )
    ok(endpoint, "marker", "add", "ROI-1", "--area", "0,0 6,0 6,6")
    ok(
        endpoint,
        "add",
        "lru2",
        "pick_stone",
        "--param",
        "target=@POI-A",
        "--param",
        "region=@ROI-1",
    )
    ok(endpoint, "barrier", "lru1-2", "lru2-2")
    before = state(endpoint)

    out = tmp_path / "saved.yaml"
    r = ok_json(endpoint, "save", str(out), "--library", str(LIBRARY))
    assert r["ok"] is True and r["value"]["file"] == str(out)
    data = yaml.safe_load(out.read_text())
    assert (out.parent / data["library"]).resolve() == LIBRARY.resolve()
    v = subprocess.run(
        [*CTL_CMD[:-1], "validate", str(out)]
        if CTL_CMD[-1] == "ctl"
        else [CTL_CMD[0], "-m", "backend.cli", "validate", str(out)],
        cwd=ROOT,
        env=env(),
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert v.returncode == 0, v.stderr

    out2 = ok(endpoint, "new", "scratch").stdout
    assert out2.startswith("started a new mission 'scratch'")
    st = state(endpoint)
    assert (
        st["name"] == "scratch"
        and all(t == [] for t in st["tasks"].values())
        and st["barriers"] == {}
    )

    out3 = ok(endpoint, "load", str(out)).stdout
    assert out3.startswith("loaded mission 'Tutorial' (2 robots, 6 skills) as a plan at revision")
    after = state(endpoint)
    for key in ("tasks", "barriers", "markers", "name"):
        assert after[key] == before[key], key

    # without --library: a loaded file never changes the server's library;
    # where the server's reference does not lead to it, the library is
    # written beside the file, which loads from there (as the console saves)
    assert after["library"] == before["library"]
    again = tmp_path / "again.yaml"
    r = ok(endpoint, "save", str(again))
    assert "note:" in r.stdout and "again.library.yaml" in r.stdout
    assert yaml.safe_load(again.read_text())["library"] == "again.library.yaml"
    assert load_mission(again)[1] == load_mission(ROOT / "missions" / "tutorial.yaml")[1]
    # next to the mission's library folder the reference is right: no note
    here = ROOT / "missions" / f"_ctl_test_{tmp_path.name}.yaml"
    try:
        ok(endpoint, "new")
        ok(endpoint, "load", str(ROOT / "missions" / "tutorial.yaml"))
        r = ok(endpoint, "save", str(here))
        assert "note:" not in r.stdout
    finally:
        here.unlink(missing_ok=True)


def test_load_invalid_file_exits_2(endpoint, tmp_path):
    before = state(endpoint)["revision"]
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        f"format: missionctl/mission@1\nlibrary: {LIBRARY}\n"
        "robots:\n  lru1: {type: lru_science}\n"
        "tasks:\n  lru1:\n    - {id: a-1, skill: drive_to, params: {goal: {x: 1, y: nope}}}\n"
    )
    r = ctl(endpoint, "load", str(bad))
    assert r.returncode == 2
    assert re.search(rf"{re.escape(str(bad))}:7:\d+: .*goal", r.stderr), r.stderr
    r = ctl(endpoint, "--json", "load", str(tmp_path / "missing.yaml"))
    assert r.returncode == 2 and json.loads(r.stdout)["code"] == "bad_file"
    assert state(endpoint)["revision"] == before


# ---------------------------------------------------------------- watch


def test_watch_prints_each_change(endpoint):
    p = subprocess.Popen(
        [*CTL_CMD, "--connect", endpoint, "watch", "--json", "--count", "2"],
        cwd=ROOT,
        env=env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        sel = selectors.DefaultSelector()
        sel.register(p.stderr, selectors.EVENT_READ)
        assert sel.select(timeout=20), "watch did not start"
        head = p.stderr.readline()
        assert head.startswith("watching mission 'Tutorial'"), head
        ok(endpoint, "add", "lru1", "recharge", "--label", "w1")
        ok(endpoint, "marker", "add", "W", "--position", "1,1")
        out, err = p.communicate(timeout=20)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 0, err
    lines = [json.loads(x) for x in out.strip().splitlines()]
    assert [x["kind"] for x in lines] == ["events", "events"]
    assert [x["op"] for x in lines] == ["add", "marker_add"]
    assert (
        lines[0]["events"][0]["ev"] == "skill_added"
        and lines[0]["events"][0]["skill"]["label"] == "w1"
    )
    assert lines[1]["revision"] == lines[0]["revision"] + 1


def test_watch_human_lines(endpoint):
    p = subprocess.Popen(
        [*CTL_CMD, "--connect", endpoint, "watch", "--count", "1"],
        cwd=ROOT,
        env=env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert p.stderr.readline().startswith("watching")
        ok(endpoint, "delete", "lru2-2")
        out, _ = p.communicate(timeout=20)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 0
    assert re.fullmatch(r"r\d+ delete by ctl-test: -lru2-2 from lru2\n", out), out


# ---------------------------------------------------------------- with robot agents


@pytest.fixture
def robots(endpoint):
    r = Robots(endpoint, "lru1:lru_science", "lru2:lru_manipulator")
    try:
        until(
            endpoint,
            lambda st: all(x["online"] for x in st["robots"].values()),
            what="robots online",
        )
        yield r
    finally:
        r.stop()


def statuses(st: dict, robot: str) -> list[str]:
    return [s["status"] for s in st["tasks"][robot]]


def test_robot_operations(endpoint, robots):
    info = ok_json(endpoint, "robots")
    lru1 = info["robots"]["lru1"]
    assert lru1["online"] is True and lru1["type"] == "lru_science"
    assert "drive_to" in lru1["manifest"]["skills"] and lru1["manifest"]["modules"] == [
        {"name": "base", "version": "1.0.0"}
    ]
    assert lru1["telemetry"] is not None and 0.0 <= lru1["telemetry"]["battery"] <= 1.0
    text = ok(endpoint, "robots").stdout
    assert "lru1 (lru_science)" in text and "online since" in text and "modules: base 1.0.0" in text

    # sync through a skill, then the rest
    out = ok(endpoint, "sync", "lru1", "--through", "lru1-1", "--wait", "20").stdout
    assert out.startswith("queued for lru1, command 1: sync lru1-1 at revision"), out
    assert "command 1 applied by lru1 after" in out and out.rstrip().endswith(": lru1-1")
    assert statuses(state(endpoint), "lru1") == ["idle_synchronized", "idle"]
    # moving a marker: the idle skill follows, the queued one is named in a note
    out = ok(endpoint, "marker", "move", "POI-A", "--pose", "11,5").stdout.splitlines()
    assert out[0].startswith("moved marker POI-A at revision")
    assert any(
        line.startswith("note: ") and "lru1-1" in line and "old value" in line for line in out[1:]
    ), out
    st = state(endpoint)
    assert (
        skill(st, "lru1-1")["params"]["goal"]["x"] == 10.0
        and skill(st, "lru1-2")["params"]["target"]["x"] == 11.0
    )
    r = ok_json(endpoint, "marker", "move", "POI-A", "--pose", "10,5")
    assert r["value"]["stale"] == ["lru1-1"] and len(r["notes"]) == 1
    r = ok_json(endpoint, "sync", "lru1", "--wait", "20")
    assert r["value"]["skills"] == ["lru1-2"] and r["answers"][0]["done"] == ["lru1-2"]
    refused(endpoint, "edit", "lru1-1", "--label", "x")  # not idle any more

    # unsync from a queued skill
    out = ok(endpoint, "unsync", "lru1", "--from", "lru1-2", "--wait", "20").stdout
    assert out.startswith("queued for lru1, command 3: unsync lru1-2"), out
    assert statuses(state(endpoint), "lru1") == ["idle_synchronized", "idle"]

    # run: everything synchronized succeeds
    ok(endpoint, "sync", "lru1")
    out = ok(endpoint, "run", "lru1").stdout
    assert out.startswith("queued for lru1, command 5: run"), out
    until(endpoint, lambda st: statuses(st, "lru1") == ["success", "success"], what="lru1 done")

    # a failure, then retry: a new attempt right after it
    # (lru1 is still running its queue: what is synchronized now starts at once)
    f = ok_json(endpoint, "add", "lru1", "recharge", "--label", "fail")["value"]["id"]
    ok(endpoint, "sync", "lru1")
    st = until(endpoint, lambda st: skill(st, f)["status"] == "failure", what="failure")
    assert skill(st, f)["status_info"] == "asked to fail"
    assert (
        "✗" in ok(endpoint, "state", "lru1").stdout or "x" in ok(endpoint, "state", "lru1").stdout
    )
    out = ok(endpoint, "retry", f, "--wait", "20").stdout
    m = re.match(rf"queued for lru1, command \d+: retry {f} as ({re.escape(f)}\.2)", out)
    assert m, out
    st = state(endpoint)
    assert ids(st, "lru1")[-2:] == [f, m.group(1)]
    assert (
        skill(st, m.group(1))["attempt"] == 2
        and skill(st, m.group(1))["status"] == "idle_synchronized"
    )

    # pause / run (resume) / stop / reset on a skill that holds
    refused(endpoint, "pause", "lru2")  # nothing running
    h = ok_json(endpoint, "add", "lru2", "recharge", "--label", "hold", "--at", "0")["value"]["id"]
    ok(endpoint, "sync", "lru2", "--through", h)
    ok(endpoint, "run", "lru2", "--expire", "10m")
    until(endpoint, lambda st: skill(st, h)["status"] == "running", what="running")
    ok(endpoint, "pause", "lru2")
    until(endpoint, lambda st: skill(st, h)["status"] == "paused", what="paused")
    ok(endpoint, "run", "lru2")
    until(endpoint, lambda st: skill(st, h)["status"] == "running", what="resumed")
    ok(endpoint, "stop", "lru2")
    until(endpoint, lambda st: skill(st, h)["status"] == "idle_synchronized", what="stopped")
    r = ok_json(endpoint, "reset", "--all", "--wait", "20")
    assert r["value"]["robots"].get("lru2") == "queued" and r["ok"] is True
    st = until(endpoint, lambda st: skill(st, h)["status"] == "idle", what="reset")
    assert statuses(st, "lru2") == ["idle", "idle", "idle"]


def test_robot_going_away_is_reported(endpoint, robots):
    robots.stop()
    until(endpoint, lambda st: not st["robots"]["lru1"]["online"], what="lru1 offline")
    assert "offline since" in ok(endpoint, "state").stdout
    # a command for it waits; one that expires first is settled so, its skills released
    r = ctl(endpoint, "sync", "lru1", "--expire", "1s", "--wait", "10")
    assert r.returncode == 1, r
    assert "expires" in r.stdout and "command 1 expired" in r.stderr, r
    assert "before it could be sent (lru1 was offline" in r.stderr
    assert statuses(state(endpoint), "lru1") == ["idle", "idle"]


def test_many_invocations_exit_cleanly(endpoint):
    """No process hangs at exit (sessions are closed)."""
    t0 = time.monotonic()
    for _ in range(5):
        ok(endpoint, "state", timeout=15)
    assert time.monotonic() - t0 < 30
