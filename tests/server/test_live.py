"""Server + robot agents (subprocesses) + clients: the mission as a live system."""

from __future__ import annotations

import asyncio
import time

import pytest

from backend.client.client import OperationRefused
from backend.client.events import ConnectionState, RobotChanged
from backend.core.model import Pose
from backend.core.ops import (
    AddBarrier,
    AddSkill,
    Cancel,
    Control,
    EditSkill,
    Retry,
    Sync,
    Unsync,
)

from .harness import drive, status, tell, until

pytestmark = pytest.mark.timeout(180)


def add(label: str, robot: str = "lru1", skill: str = "recharge", **kw):
    return AddSkill(robot=robot, skill=skill, label=label, **kw)


def test_add_edit_sync_run_to_success(cluster):
    cluster.start_robots("lru1:lru_science", "lru2:lru_manipulator")

    async def scenario(c):
        sid = (await c.submit(add("first"))).value["id"]
        await c.submit(EditSkill(id=sid, label="charge up", params={"target_level": 0.8}))
        await c.submit(Sync(robot="lru1", through=sid))
        m = await until(c, lambda m: status(m, sid) == "idle_synchronized")
        # synchronized up to and including it: the tutorial's two skills first
        assert [s.status.value for s in m.tasks["lru1"]][:3] == ["idle_synchronized"] * 3
        await c.submit(Control(op="run", robot="lru1"))
        m = await until(c, lambda m: status(m, sid) == "success")
        done = m.find(sid)[2]
        assert done.label == "charge up" and done.params["target_level"] == 0.8
        assert done.started_at is not None and done.finished_at is not None
        assert all(s.status.value == "success" for s in m.tasks["lru1"])

    drive(cluster, scenario)


def test_unsync_before_start_returns_skills_in_order(cluster):
    cluster.start_robots("lru1:lru_science", "lru2:lru_manipulator")

    async def scenario(c):
        await c.submit(Sync(robot="lru1"))
        await until(c, lambda m: status(m, "lru1-2") == "idle_synchronized")
        reply = await c.submit(Unsync(robot="lru1"))
        done = await c.wait_command(reply.value["command"], 15)
        assert done.state.value == "acked" and done.kept == []
        assert done.done == ["lru1-1", "lru1-2"]
        m = await until(c, lambda m: status(m, "lru1-1") == "idle")
        assert [s.id for s in m.tasks["lru1"]] == ["lru1-1", "lru1-2"]

    drive(cluster, scenario)


def test_unsync_while_the_robot_starts_the_same_skill(cluster):
    # a one-way delay keeps the robot's "running" report away from the server
    # while the unsync is planned: the server asks for a skill already started
    cluster.start_robots("lru1:lru_science", "lru2:lru_manipulator", delay=0.5)

    async def scenario(c):
        h = (await c.submit(add("hold first"), timeout=15)).value["id"]
        await c.submit(EditSkill(id="lru1-1", label="hold"))
        a = (await c.submit(add("hold A"))).value["id"]  # stays running once started
        b = (await c.submit(add("B"))).value["id"]
        # queue: lru1-1 (hold), lru1-2, h (hold), a, b
        await c.submit(Sync(robot="lru1", through=b), timeout=15)
        await c.submit(Control(op="run", robot="lru1"), timeout=15)
        await until(c, lambda m: status(m, "lru1-1") == "running")
        await tell(c, "lru1", "release", {"id": "lru1-1"})  # lru1-2 follows at once, then h
        await until(c, lambda m: status(m, h) == "running")
        await tell(c, "lru1", "release", {"id": h})  # the robot starts A right away
        reply = await c.submit(Unsync(robot="lru1", from_id=a), timeout=15)
        assert reply.value["state"] == "queued"  # returns before the robot answers
        done = await c.wait_command(reply.value["command"], 15)
        assert done.kept == [a] and done.done == [b], done  # the robot's truth
        m = await until(c, lambda m: status(m, b) == "idle")
        assert status(m, a) == "running"
        await tell(c, "lru1", "release", {"id": a})
        await until(c, lambda m: status(m, a) == "success")
        order = [s.id for s in m.tasks["lru1"]]
        assert order.index(a) < order.index(b)

    drive(cluster, scenario)


def test_barrier_neither_starts_before_both_are_ready(cluster):
    cluster.start_robots("lru1:lru_science", "lru2:lru_manipulator")

    async def scenario(c):
        p = (
            await c.submit(add("meet", skill="identify_stone", params={"target": {"x": 1, "y": 1}}))
        ).value["id"]
        q = (
            await c.submit(
                add(
                    "meet",
                    robot="lru2",
                    skill="identify_stone",
                    params={"target": {"x": 1, "y": 1}},
                )
            )
        ).value["id"]
        await c.submit(AddBarrier(ids=[p, q]))
        await c.submit(Sync(robot="lru1"))
        await c.submit(Sync(robot="lru2"))
        await c.submit(Control(op="run", robot="lru1"))
        m = await until(c, lambda m: status(m, p) == "synchwaiting")
        assert status(m, q) == "idle_synchronized"
        released_at = time.time()
        await c.submit(Control(op="run", robot="lru2"))
        m = await until(c, lambda m: status(m, p) == "success" and status(m, q) == "success")
        for sid in (p, q):
            assert m.find(sid)[2].started_at.timestamp() >= released_at - 0.5

    drive(cluster, scenario)


def test_failure_halts_then_retry_succeeds(cluster):
    cluster.start_robots("lru1:lru_science", "lru2:lru_manipulator")

    async def scenario(c):
        f = (await c.submit(add("flaky"))).value["id"]
        n = (await c.submit(add("next"))).value["id"]
        await c.submit(Sync(robot="lru1"))
        await c.submit(Control(op="run", robot="lru1"))
        m = await until(c, lambda m: status(m, f) == "failure")
        assert status(m, n) == "idle_synchronized"  # the queue halted
        assert "first attempt fails" in m.find(f)[2].status_info
        reply = await c.submit(Retry(id=f))
        retry_id = reply.value["id"]
        m = await until(c, lambda m: status(m, retry_id) == "idle_synchronized")
        ids = [s.id for s in m.tasks["lru1"]]
        assert ids.index(retry_id) == ids.index(f) + 1
        await c.submit(Control(op="run", robot="lru1"))
        m = await until(c, lambda m: status(m, n) == "success")
        retried = m.find(retry_id)[2]
        assert retried.status.value == "success" and retried.attempt == 2
        assert status(m, f) == "failure"  # the log keeps the failed attempt

    drive(cluster, scenario)


def test_killed_robot_is_offline_and_its_partner_says_so(cluster):
    cluster.start_robots("lru1:lru_science")
    lru2 = cluster.start_robots("lru2:lru_manipulator")

    async def scenario(c):
        p = (
            await c.submit(add("meet", skill="identify_stone", params={"target": {"x": 1, "y": 1}}))
        ).value["id"]
        q = (
            await c.submit(
                add(
                    "meet",
                    robot="lru2",
                    skill="identify_stone",
                    params={"target": {"x": 1, "y": 1}},
                )
            )
        ).value["id"]
        await c.submit(AddBarrier(ids=[p, q]))
        await c.submit(Sync(robot="lru1"))
        await c.submit(Sync(robot="lru2"))
        await c.submit(Control(op="run", robot="lru1"))
        await until(c, lambda m: status(m, p) == "synchwaiting")
        went = asyncio.Event()
        c.add_listener(
            lambda e: (
                went.set()
                if isinstance(e, RobotChanged) and e.robot.name == "lru2" and not e.robot.online
                else None
            )
        )
        lru2.kill()
        t0 = time.monotonic()
        await asyncio.wait_for(went.wait(), 5)
        assert time.monotonic() - t0 < 2.0
        assert c.robots["lru2"].online is False
        m = await until(c, lambda m: "offline" in m.find(p)[2].status_info)
        assert "lru2" in m.find(p)[2].status_info

    drive(cluster, scenario)


def test_server_killed_and_restarted_loses_nothing(cluster):
    cluster.start_robots("lru1:lru_science", "lru2:lru_manipulator")

    async def scenario(c):
        h = (await c.submit(add("hold"))).value["id"]
        await c.submit(Sync(robot="lru1"))
        await c.submit(Control(op="run", robot="lru1"))
        await until(c, lambda m: status(m, h) == "running")
        before = c.mission.model_copy(deep=True)
        states = []
        c.add_listener(lambda e: states.append(e.state) if isinstance(e, ConnectionState) else None)
        cluster.server.kill()  # SIGKILL mid-mission
        cluster.start_server()
        m = await until(
            c, lambda m: c.connected and c.server_id is not None and "reconnecting" in states, 20
        )
        assert m.revision >= before.revision
        for robot, task in before.tasks.items():
            assert [s.id for s in m.tasks[robot]] == [s.id for s in task]
        assert status(m, h) == "running"
        # the robot reconnects and registers again with its queue (reconciled)
        await until(c, lambda m: c.robots["lru1"].online and c.robots["lru1"].since is not None, 20)
        await tell(c, "lru1", "release", {"id": h})
        await until(c, lambda m: status(m, h) == "success", 20)

    drive(cluster, scenario)


def test_two_clients_editing_the_same_skill(cluster):
    async def scenario(a, b):
        seen = a.revision
        assert b.revision == seen
        await a.submit(EditSkill(id="lru1-1", label="from a"), expected_revision=seen)
        with pytest.raises(OperationRefused) as refused:
            await b.submit(EditSkill(id="lru1-1", label="from b"), expected_revision=seen)
        assert refused.value.code == "stale"
        m = await until(b, lambda m: m.find("lru1-1")[2].label == "from a")
        assert m.find("lru1-1")[2].label == "from a"

    drive(cluster, scenario, clients=2)


def test_a_retried_request_is_applied_once(cluster):
    async def scenario(c):
        first = await c.submit(add("once"), request_id="same")
        again = await c.submit(add("once"), request_id="same")
        assert again.duplicate and again.revision == first.revision
        m = await until(c, lambda m: m.revision == first.revision)
        assert [s.label for s in m.tasks["lru1"]].count("once") == 1

    drive(cluster, scenario)


def test_sync_to_an_absent_robot_waits_for_it(cluster):
    """A robot not connected gets its commands when it comes: the operator's
    sync returns at once, its skills are uplinking meanwhile; a cancel of a
    command that never left is final."""

    async def scenario(c):
        first = await c.submit(Sync(robot="lru1", through="lru1-1"))
        assert first.value["state"] == "queued" and first.value["skills"] == ["lru1-1"]
        await c.submit(Cancel(command=first.value["command"]))
        # the cancel's reply may come before the command's own event reaches this mirror
        cancelled = await c.wait_command(first.value["command"], 10)
        assert cancelled.state.value == "cancelled"
        m = c.mission
        assert status(m, "lru1-1") == "idle" and c.pending("lru1") == []
        again = await c.submit(Sync(robot="lru1"))
        with pytest.raises(OperationRefused) as refused:  # uplinking skills are locked
            await c.submit(EditSkill(id="lru1-1", label="changed"))
        assert refused.value.code == "locked" and "command 2" in str(refused.value)
        cluster.start_robots("lru1:lru_science")
        done = await c.wait_command(again.value["command"], 20)
        assert done.state.value == "acked" and done.done == ["lru1-1", "lru1-2"]
        m = await until(c, lambda m: status(m, "lru1-2") == "idle_synchronized")
        assert status(m, "lru1-1") == "idle_synchronized"

    drive(cluster, scenario)


def test_a_second_client_sees_the_first_ones_edit(cluster):
    async def scenario(a, b):
        r = await a.submit(EditSkill(id="lru2-1", params={"goal": Pose(x=7, y=1).model_dump()}))
        m = await until(b, lambda m: m.revision == r.revision, 5)
        assert m.find("lru2-1")[2].params["goal"]["x"] == 7

    drive(cluster, scenario, clients=2)


CLOSE_NOW = """
import asyncio, sys
from backend.client.client import MissionClient
client = MissionClient(sys.argv[1])
async def main():
    await client.connect()
    print("revision", client.revision, flush=True)
asyncio.run(main())  # the loop is gone; the session is still open
client.close_now()
print("closed", client.session is None, flush=True)
"""


def test_close_now_lets_a_process_exit_after_its_loop_ended(cluster):
    import subprocess
    import sys

    # a Zenoh session left open keeps a process from exiting: close_now is the way out
    # once no event loop runs any more (the console closes with it at the last moment)
    p = subprocess.run(
        [sys.executable, "-c", CLOSE_NOW, cluster.endpoint],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert p.returncode == 0, p.stderr
    assert "closed True" in p.stdout and "revision" in p.stdout
