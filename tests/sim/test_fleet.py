"""The simulated fleet against the real mission server (both as subprocesses),
driven by a scripted operator through backend.client.client.MissionClient."""

from __future__ import annotations

import asyncio
import json
import math
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from backend import transport
from backend.client.events import ClientEvent, TelemetryReceived
from backend.core.ops import AddBarrier, AddSkill, Control, EditSkill, Sync
from backend.protocol import mapfeed as mf

from ..cli.helpers import ctl
from .conftest import ROOT, Stack, connect, skill, status_of, world_file


async def add(
    client, robot: str, skill_name: str, params: dict, *, at: int = 0, label: str = ""
) -> str:
    reply = await client.submit(
        AddSkill(robot=robot, skill=skill_name, params=params, at=at, label=label)
    )
    return reply.value["id"]


async def test_scripted_operator_plays_the_pilot_mission(stack: Stack) -> None:
    """The opening mission: explore until an RSS is found, identify a stone with
    LRU1+LRU2 at a barrier, pick it, bring it to the lander: the score reaches the
    region's top score (RSS-A at POI-A, a poor region near the lander: 0.5)."""
    client, watch = await connect(stack, speed=100, seed=1)
    endpoint = stack.endpoint
    try:
        # the map feed: deltas from now on, then the snapshot (a late joiner)
        mirror = mf.MapMirror()
        loop = asyncio.get_running_loop()
        gaps: list[int] = []
        progressed = asyncio.Event()

        def apply(d: mf.MapDelta) -> None:
            if not mirror.apply_delta(d):
                gaps.append(d.seq)
            progressed.set()

        def on_delta(msg: transport.Message) -> None:
            d = mf.MapDelta.model_validate_json(msg.payload)
            loop.call_soon_threadsafe(apply, d)

        sub = transport.subscribe(client.session, mf.KEY_MAP_DELTA, on_delta)
        snap = mf.MapSnapshot.model_validate_json(
            await transport.query(client.session, mf.KEY_MAP_SNAPSHOT, b"")
        )
        mirror.apply_snapshot(snap)
        assert mirror.meta is not None and mirror.meta.width * mirror.meta.cell >= 200

        m = client.mission
        assert m is not None and m.barriers["b1"].skills == ["lru1-3", "lru2-3"]
        # the operator edits the plan before synchronizing it: a shorter survey that ends
        # back at POI-A, inside coverage (else its reports wait until it comes back)
        await client.submit(
            EditSkill(id="lru1-2", params={"max_duration": 150, "return_to_start": True})
        )
        # 1. LRU1 drives to POI-A and explores the east plain; the lander shelves the Wi-Fi box
        await client.submit(Sync(robot="lru1", through="lru1-2"))
        await client.submit(Sync(robot="lander"))
        await client.submit(Control(op="run", robot="lru1"))
        await client.submit(Control(op="run", robot="lander"))
        await client.wait_for(lambda m: status_of(m, "lru1-2") == "success", 40)
        status = await watch.query()
        assert "RSS-A" in status.rss_found
        # 2. LRU2 takes the sample box and joins LRU1 at the barrier; pick, return, drop
        await client.submit(Sync(robot="lru2"))
        await client.submit(Sync(robot="lru1", through="lru1-3"))
        await client.submit(Control(op="run"))
        await client.wait_for(
            lambda m: status_of(m, "lru2-3") in ("synchwaiting", "running", "success"), 20
        )
        await client.wait_for(lambda m: status_of(m, "lru2-6") in ("success", "failure"), 60)
        m = client.mission
        failed = [
            (s.id, s.status_info)
            for t in m.tasks.values()
            for s in t
            if s.status.value == "failure"
        ]
        assert not failed, failed
        # handlers' results reach the operator as the success's status information
        identified = [
            s.status_info for t in m.tasks.values() for s in t if s.skill == "identify_stone"
        ]
        assert identified and all(i.startswith("identified RSS-A-s") for i in identified), (
            identified
        )
        status = await watch.until(lambda s: s.score >= 0.5, 10, "the score")
        # deterministic for seed 1: the stone nearest POI-A in RSS-A, top score 0.5
        assert [(d.stone, d.score, d.by) for d in status.delivered] == [("RSS-A-s1", 0.5, "lru2")]
        assert status.score == pytest.approx(0.5)
        _results_and_exchanges_of_the_opening_mission(m, await watch.truth())

        # the map seen by a console (live deltas): explored cells, RSS-A and the delivered stone
        def delivered_on_map() -> bool:
            objs = mirror.objects
            return objs is not None and any(
                s.id == "RSS-A-s1" and s.state == "delivered" for s in objs.stones
            )

        await asyncio.wait_for(_until(delivered_on_map, progressed), 10)
        assert "RSS-A" in {r.rss for r in mirror.objects.rss}
        assert (mirror.layers["terrain"] > 0).sum() > 200
        # ... identical to what a late joiner gets from the snapshot
        final = mf.MapSnapshot.model_validate_json(
            await transport.query(client.session, mf.KEY_MAP_SNAPSHOT, b"")
        )
        await asyncio.wait_for(_until(lambda: mirror.seq >= final.seq, progressed), 10)
        sub.undeclare()
        assert not gaps
        fresh = mf.MapMirror()
        fresh.apply_snapshot(final)
        if mirror.seq == fresh.seq:  # nothing changed in between (the robots are idle)
            for layer in mf.LAYERS:
                assert np.array_equal(mirror.layers[layer], fresh.layers[layer])
            assert mirror.objects == fresh.objects
        # `missionctl sim-status --json` says the same
        out = subprocess.run(
            [sys.executable, "-m", "backend.cli", "sim-status", "--connect", endpoint, "--json"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert out.returncode == 0, out.stderr
        assert json.loads(out.stdout)["score"] == pytest.approx(0.5)
    finally:
        watch.close()
        await client.close()


def _results_and_exchanges_of_the_opening_mission(m, truth: mf.SimTruth) -> None:
    # the results tell what happened
    results = {s.skill: s.status_info for t in m.tasks.values() for s in t}
    assert results["pick_stone"].startswith("picked RSS-A-s1 of RSS-A (score 0.5)")
    assert results["drop_stone"] == "delivered RSS-A-s1 of RSS-A +0.5: +0.5; score 0.5"
    # LRU2 asked LRU1 where the stone is and got the answer; it told the others about the boxes
    assert truth.exchanges["asks"] >= 2 and truth.exchanges["answered"] >= 2
    assert truth.exchanges["tells"] >= 3
    assert (
        any(
            "lru2 asked lru1 about stone: RSS-A-s1" in line
            for line in truth.exchange_log + truth.events
        )
        or truth.exchanges["answered"] >= 2
    )


async def _until(pred, progressed: asyncio.Event) -> None:
    while not pred():
        progressed.clear()
        await progressed.wait()


async def test_battery_runs_out_on_a_long_drive_and_recharge_restores_it(
    stack: Stack, tmp_path: Path
) -> None:
    world = world_file(tmp_path, robots={"lru1": {"battery": 0.10}})  # ~17 m above the reserve
    client, watch = await connect(stack, speed=80, world=world)
    try:
        far = await add(
            client, "lru1", "drive_to", {"goal": {"x": 0.0, "y": -55.0}}, label="too far"
        )
        await client.submit(Sync(robot="lru1", through=far))
        await client.submit(Control(op="run", robot="lru1"))
        m = await client.wait_for(lambda m: status_of(m, far) in ("success", "failure"), 30)
        s = skill(m, far)
        assert s.status.value == "failure"
        found = re.search(r"battery empty after (\d+) m of (\d+) m", s.status_info)
        assert found and "recharge at the lander" in s.status_info, s.status_info
        assert 12 <= int(found.group(1)) < int(found.group(2))
        st = await watch.truth()
        assert st.robots["lru1"].battery == pytest.approx(0.05, abs=0.005)
        assert not st.robots["lru1"].docked
        # the operator decides: a recharge first
        rc = await add(client, "lru1", "recharge", {"target_level": 0.95})
        await client.submit(Sync(robot="lru1", through=rc))
        await client.submit(Control(op="run", robot="lru1"))
        await client.wait_for(lambda m: status_of(m, rc) in ("success", "failure"), 30)
        assert status_of(client.mission, rc) == "success", skill(client.mission, rc).status_info
        st = await watch.truth()
        assert st.robots["lru1"].battery >= 0.95 and st.robots["lru1"].docked
    finally:
        watch.close()
        await client.close()


async def test_robot_out_of_coverage_cannot_be_reached_and_reports_arrive_after_return(
    stack: Stack,
) -> None:
    client, watch = await connect(stack, speed=50)
    try:
        out = await add(
            client, "lru1", "drive_to", {"goal": {"x": 85.0, "y": 0.0}}, at=0, label="out of range"
        )
        area = [
            {"x": 80.0, "y": -8.0},
            {"x": 95.0, "y": -8.0},
            {"x": 95.0, "y": 8.0},
            {"x": 80.0, "y": 8.0},
        ]
        survey = await add(
            client,
            "lru1",
            "explore",
            {"area": area, "max_duration": 120},
            at=1,
            label="survey out there",
        )
        back = await add(
            client, "lru1", "drive_to", {"goal": {"x": 10.0, "y": 2.0}}, at=2, label="come back"
        )
        await client.submit(Sync(robot="lru1", through=back))
        await client.submit(Control(op="run", robot="lru1"))
        await watch.until(lambda s: not s.robots["lru1"].in_range, 30, "lru1 out of range")
        # protocol 2: the operator is not refused; the command waits in lru1's
        # uplink (its skill "uplinking") until lru1 can hear the ground again
        queued = await client.submit(Sync(robot="lru1", through="lru1-1"))
        assert queued.value["state"] == "queued"
        assert status_of(client.mission, "lru1-1") == "idle"  # not on the robot yet
        assert status_of(client.mission, back) == "idle_synchronized"  # its reports wait aboard
        await watch.until(lambda s: s.robots["lru1"].in_range, 30, "lru1 back in range")
        m = await client.wait_for(lambda m: status_of(m, back) in ("success", "failure"), 30)
        assert [status_of(m, i) for i in (out, survey, back)] == ["success", "success", "success"]
        done = await client.wait_command(queued.value["command"], 30)  # delivered on return
        assert done.state.value == "acked" and done.done == ["lru1-1"]
        # 3 answers (sync, run, the sync sent on return) + running and success of
        # each skill at least, in one sequence (lru1, still in run mode, may
        # start lru1-1 at once)
        m = client.mission
        assert m.report_seqs["lru1"] >= 9 and status_of(m, "lru1-1") != "idle"
        # what it mapped out there reached the ground view once it was back
        snap = mf.MapSnapshot.model_validate_json(
            await transport.query(client.session, mf.KEY_MAP_SNAPSHOT, b"")
        )
        mirror = mf.MapMirror()
        mirror.apply_snapshot(snap)
        cell = mirror.cell_of(88.0, 0.0)
        assert cell is not None and mirror.layers["terrain"][cell] != mf.T_UNKNOWN
    finally:
        watch.close()
        await client.close()


async def test_drone_flight_longer_than_its_battery_fails_safely_and_landing_recharges(
    stack: Stack, tmp_path: Path
) -> None:
    world = world_file(tmp_path, robots={"ardea": {"battery": 0.3}})
    client, watch = await connect(stack, speed=30, world=world)  # a hovering drone drains fast
    try:
        fly = await add(
            client, "ardea", "fly_to", {"goal": {"x": 150.0, "y": -150.0}}, at=1, label="too far"
        )
        await client.submit(Sync(robot="ardea", through=fly))
        await client.submit(Control(op="run", robot="ardea"))
        m = await client.wait_for(lambda m: status_of(m, fly) in ("success", "failure"), 30)
        assert status_of(m, "ardea-1") == "success"
        s = skill(m, fly)
        assert s.status.value == "failure" and "refused before the flight" in s.status_info, (
            s.status_info
        )
        st = await watch.truth()
        assert st.robots["ardea"].airborne  # still hovering safely near the lander
        assert st.robots["ardea"].battery > 0.2
        land = await add(client, "ardea", "land", {"where": "lander_pad"}, at=0)
        await client.submit(Sync(robot="ardea", through=land))
        await client.submit(Control(op="run", robot="ardea"))
        await client.wait_for(lambda m: status_of(m, land) == "success", 30)
        st = await watch.until(
            lambda s: s.robots["ardea"].docked and s.robots["ardea"].battery >= 0.9,
            30,
            "charging on the pad",
        )
        assert not st.robots["ardea"].airborne
    finally:
        watch.close()
        await client.close()


async def test_pause_stop_and_run_restarts_the_skill(stack: Stack) -> None:
    client, watch = await connect(stack, speed=40)
    try:
        drive = await add(client, "lru1", "drive_to", {"goal": {"x": -50.0, "y": -30.0}}, at=0)
        await client.submit(Sync(robot="lru1", through=drive))
        await client.submit(Control(op="run", robot="lru1"))

        def telemetry_progress(minimum: float):
            def pred(_m) -> bool:
                t = client.telemetry.get("lru1")
                return t is not None and t.skill == drive and (t.progress or 0) >= minimum

            return pred

        await client.wait_for(telemetry_progress(0.2), 20)
        total_first = _total_metres(client.telemetry["lru1"].info)
        await client.submit(Control(op="pause", robot="lru1"))
        await client.wait_for(lambda m: status_of(m, drive) == "paused", 10)
        paused_at = (await watch.truth()).robots["lru1"]
        # several telemetry samples later it has not moved
        seen = await _telemetry_samples(client, "lru1", 4)  # the first may have been on its way
        assert all(
            abs(t.pose.x - paused_at.x) < 0.01 and abs(t.pose.y - paused_at.y) < 0.01
            for t in seen[1:]
        )
        assert (await watch.truth()).robots["lru1"].odometer_m == paused_at.odometer_m
        await client.submit(Control(op="run", robot="lru1"))  # resume
        await client.wait_for(lambda m: status_of(m, drive) == "running", 10)
        await client.wait_for(telemetry_progress(0.5), 20)
        await client.submit(Control(op="stop", robot="lru1"))
        await client.wait_for(lambda m: status_of(m, drive) == "idle_synchronized", 10)
        await client.submit(Control(op="run", robot="lru1"))  # starts it from the beginning
        await client.wait_for(lambda m: status_of(m, drive) == "running", 10)

        # a new run of the handler: a new route from where it stopped, so a shorter total
        assert total_first is not None

        def restarted(_m) -> bool:
            t = client.telemetry.get("lru1")
            total = _total_metres(t.info) if t is not None and t.skill == drive else None
            return total is not None and total < total_first * 0.6

        await client.wait_for(restarted, 10)
        await client.wait_for(lambda m: status_of(m, drive) == "success", 30)
        st = await watch.truth()
        assert abs(st.robots["lru1"].x + 50.0) < 1.0 and abs(st.robots["lru1"].y + 30.0) < 1.0
    finally:
        watch.close()
        await client.close()


def _total_metres(info: str) -> float | None:
    m = re.search(r"(\d+) of (\d+) m", info or "")
    return float(m.group(2)) if m else None


async def _telemetry_samples(client, robot: str, n: int) -> list:
    got: list = []
    done = asyncio.Event()

    def listener(event: ClientEvent) -> None:
        if isinstance(event, TelemetryReceived) and event.telemetry.robot == robot:
            got.append(event.telemetry)
            if len(got) >= n:
                done.set()

    client.add_listener(listener)  # (MissionClient has no remove_listener: it just stops mattering)
    await asyncio.wait_for(done.wait(), 10)
    return got[:n]


async def test_link_delay_applies_between_ground_and_robots(stack: Stack) -> None:
    # 20 s of sim time one way: 0.4 s of wall time at 50x
    client, watch = await connect(stack, speed=50, extra=["--link-delay", "20s"])
    try:
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        reply = await client.submit(Sync(robot="lander"))  # queued: the operator never waits
        assert loop.time() - t0 < 0.4
        await client.wait_command(reply.value["command"], 5)  # the robot's answer: there and back
        assert loop.time() - t0 >= 0.8
        await client.wait_for(lambda m: status_of(m, "lander-1") == "idle_synchronized", 5)
        t0 = loop.time()
        await client.submit(Control(op="run", robot="lander"))
        m = await client.wait_for(lambda m: status_of(m, "lander-1") == "success", 20)
        assert loop.time() - t0 >= 0.8  # the command, then the reports: 2 x 0.4 s at least
        assert skill(m, "lander-1").status.value == "success"
        assert (await watch.query()).link_delay_s == pytest.approx(20)
    finally:
        watch.close()
        await client.close()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_sim_exits_cleanly_on_signals(stack: Stack, sig: int) -> None:
    stack.start(speed=50)
    assert stack.sim is not None
    stack.sim.signal(sig)
    assert stack.sim.p.wait(10) == 0, stack.sim.output()


def test_sim_reports_bad_files_and_unreachable_server(tmp_path: Path) -> None:
    bad = tmp_path / "world.yaml"
    bad.write_text("format: missionctl/world@1\nrss:\n  - {name: X, x: 0, y: 0}\n")
    base = [
        sys.executable,
        "-m",
        "backend.cli",
        "sim",
        "--mission",
        str(ROOT / "missions" / "mars_sample_return.yaml"),
    ]
    out = subprocess.run(
        base + ["--world", str(bad)], cwd=ROOT, capture_output=True, text=True, timeout=30
    )
    assert out.returncode == 2
    assert f"{bad}:3:" in out.stderr and "max_score" in out.stderr and "Traceback" not in out.stderr
    port = transport.free_port()
    out = subprocess.run(
        base + ["--connect", transport.loopback_endpoint(port), "--connect-timeout", "0"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert out.returncode == 3 and "cannot reach" in out.stderr, out.stderr


async def test_sim_status_shows_what_the_robots_reported_and_the_truth_only_when_asked(
    stack: Stack,
) -> None:
    """LRU1 explores behind the ridge, out of coverage, and discovers RSS-C there: the
    ground knows nothing of it (nor where LRU1 is now) until LRU1 is back in range;
    `sim-status --truth` shows it at once, for evaluation."""
    client, watch = await connect(stack, speed=50)
    try:
        beyond = [
            {"x": -60.0, "y": 76.0},
            {"x": 0.0, "y": 76.0},
            {"x": 0.0, "y": 120.0},
            {"x": -60.0, "y": 120.0},
        ]
        steps = [
            ("drive_to", {"goal": {"x": -30.0, "y": 76.0}, "speed": 1.0}),
            ("explore", {"area": beyond, "max_duration": 600}),
            ("drive_to", {"goal": {"x": 5.0, "y": 5.0}, "speed": 1.0}),
        ]
        ids = [await add(client, "lru1", s, p, at=i) for i, (s, p) in enumerate(steps)]
        await client.submit(Sync(robot="lru1", through=ids[-1]))
        await client.submit(Control(op="run", robot="lru1"))

        async def found_out_there() -> mf.SimTruth:
            while True:  # evaluation: polling the truth is the test's privilege
                truth = await watch.truth()
                c = next(g for g in truth.regions if g.rss == "RSS-C")
                if "lru1" in c.found_by and not truth.robots["lru1"].in_range:
                    return truth
                watch.changed.clear()
                await asyncio.wait_for(watch.changed.wait(), 5)  # the next live status

        truth = await asyncio.wait_for(found_out_there(), 60)
        assert math.hypot(truth.robots["lru1"].x, truth.robots["lru1"].y) > 70
        out = _sim_status(stack.endpoint, "--json")
        ground = mf.SimStatus.model_validate_json(out)
        assert ground.truth is None
        assert "RSS-C" not in ground.rss_found  # it waits aboard lru1
        heard = ground.robots["lru1"]
        assert not heard.in_range and heard.heard_at is not None
        assert heard.heard_at < ground.sim_time
        assert math.hypot(heard.x, heard.y) <= 75  # where it was last heard, at the edge
        assert ground.explored < truth.explored
        text = _sim_status(stack.endpoint)
        assert "RSS-C" not in text and "TRUTH" not in text and "OUT OF RANGE" in text
        assert "as reported by the robots" in text and "sim time" in text
        # everything the ground shows came from the robots: it is on the operator's map too
        snap = mf.MapSnapshot.model_validate_json(
            await transport.query(client.session, mf.KEY_MAP_SNAPSHOT, b"")
        )
        assert set(ground.rss_found) == {r.rss for r in snap.objects.rss}
        assert ground.score == snap.objects.score == 0.0
        told = _sim_status(stack.endpoint, "--truth")
        assert "TRUTH" in told and "RSS-C" in told and "found by lru1" in told
        # back in range, what it learnt reaches the ground
        await watch.until(lambda s: "RSS-C" in s.rss_found, 60, "RSS-C reported")
    finally:
        watch.close()
        await client.close()


def _sim_status(endpoint: str, *args: str) -> str:
    out = subprocess.run(
        [sys.executable, "-m", "backend.cli", "sim-status", "--connect", endpoint, *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert out.returncode == 0, out.stderr
    return out.stdout


async def test_a_barrier_needs_a_link_between_the_partners(stack: Stack) -> None:
    """LRU1 waits at its barrier beyond coverage, LRU2 at the lander: both are ready but
    cannot talk (robots talk through the network only), so neither starts; LRU2, in
    range, shows LRU1 as unreachable."""
    client, watch = await connect(stack, speed=50)
    try:
        g = {"x": 54.0, "y": -84.0}  # RSS-G, out there
        out = await add(client, "lru1", "drive_to", {"goal": {"x": 0.0, "y": -80.0}}, at=0)
        a = await add(
            client,
            "lru1",
            "identify_stone",
            {"target": g, "search_radius": 6.0, "partner": "lru2"},
            at=1,
        )
        b = await add(
            client,
            "lru2",
            "identify_stone",
            {"target": g, "search_radius": 6.0, "partner": "lru1"},
            at=0,
        )
        bid = (await client.submit(AddBarrier(ids=[a, b]))).value["barrier"]
        # the plan checks say so before it goes up (issue 35: no error, both rows stale)
        check = await asyncio.to_thread(ctl, stack.endpoint, "check", "--json")
        assert check.returncode == 1, check.stderr
        findings = {f["id"]: f for f in json.loads(check.stdout)["findings"]}
        f = findings[f"coverage.barrier:{bid}"]
        assert f["severity"] == "error" and "lru1 waits at (0, -80)" in f["message"], f
        assert findings[f"coverage.partner:{a}/partner"]["severity"] == "warning"
        await client.submit(Sync(robot="lru1", through=a))
        await client.submit(Sync(robot="lru2", through=b))
        await client.submit(Control(op="run", robot="lru1"))
        await client.submit(Control(op="run", robot="lru2"))
        await watch.until(lambda s: not s.robots["lru1"].in_range, 30, "lru1 out of range")
        m = await client.wait_for(lambda m: "lru1 (unreachable)" in skill(m, b).status_info, 30)
        assert status_of(m, b) == "synchwaiting"
        t0 = (await watch.query()).sim_time
        await watch.until(lambda s: s.sim_time > t0 + 300, 30, "300 sim-seconds later")
        assert status_of(client.mission, b) == "synchwaiting"  # still: no link, no start
        assert status_of(client.mission, out) == "running"  # its success waits aboard lru1
        truth = await watch.truth()
        assert all(s.state == "hidden" for s in truth.stones)
        assert truth.robots["lru1"].activity is None and truth.robots["lru2"].activity is None
        await client.submit(Control(op="stop", robot="lru2"))
        await client.wait_for(lambda m: status_of(m, b) == "idle_synchronized", 10)
    finally:
        watch.close()
        await client.close()
