"""Contingencies live: under a link delay, a drive whose goal is impassable
takes its on_failure branch on board (a goto, with the robot's own drive
skill), and ctl shows which branch ran and why. The delay is injected in sim
time (--link-delay at --speed), never waited out."""

from __future__ import annotations

import asyncio

from backend.core.model import FINISHED, Goto, Policies, Status
from backend.core.ops import AddSkill, Control, Sync

from ..cli.helpers import ok
from .conftest import Stack, connect, skill

CRATER = "{x: 62, y: 38}"  # the crater north-east of the lander: impassable (worlds/mars.yaml)


async def test_an_impassable_drive_goes_to_its_rally_point_on_board(stack: Stack) -> None:
    client, watch = await connect(stack, speed=50, seed=1, extra=["--link-delay", "60s"])
    endpoint = stack.endpoint
    try:
        added = await asyncio.to_thread(
            ok,
            endpoint,
            "add",
            "lru1",
            "drive_to",
            "--param",
            f"goal={CRATER}",
            "--at",
            "0",
            "--on-failure",
            "goto:POI-A",
            "--json",
        )
        sid = next(s.id for s in client.mission.tasks["lru1"] if s.status == Status.IDLE)
        assert skill(client.mission, sid).policies.on_failure == Goto(goto="POI-A"), added.stdout
        await client.submit(Sync(robot="lru1", through=sid))
        await client.submit(Control(op="run", robot="lru1"))

        def branched(m) -> bool:
            s = skill(m, sid)
            return s.status == Status.FAILURE and s.branch is not None

        await client.wait_for(branched, 60.0)
        s = skill(client.mission, sid)
        assert (s.branch.trigger, s.branch.branch) == ("failure", "goto")
        assert "impassable" in s.branch.reason
        assert "→ goto to POI-A: drive_to done" in s.status_info
        # the robot drove to the rally point itself, then halted there
        truth = await watch.truth()
        lru1 = truth.robots["lru1"]
        assert abs(lru1.x - 29.0) < 2.0 and abs(lru1.y - 23.0) < 2.0, lru1
        assert [e.id for e in client.mission.tasks["lru1"] if e.status != Status.IDLE] == [sid]
        shown = await asyncio.to_thread(ok, endpoint, "state", "lru1")
        line = next(ln for ln in shown.stdout.splitlines() if sid in ln)
        assert "[on failure: goto]" in line and "impassable" in line, line
        assert "✗→goto@POI-A" in line or "X->goto@POI-A" in line, line
    finally:
        watch.close()
        await client.close()


async def test_the_lander_shelves_the_wifi_box_before_lru2_deploys_it(stack: Stack) -> None:
    """The newcomer's mistake (issue 29): run together, LRU2 asked for the box before
    it was on the shelf. With `after`, LRU2 waits on board for the lander's success."""
    client, watch = await connect(stack, speed=100, seed=1, extra=["--link-delay", "30s"])
    endpoint = stack.endpoint
    try:
        reply = await client.submit(
            AddSkill(
                robot="lru2",
                skill="deploy_wifi_box",
                params={"goal": {"x": 20.0, "y": 5.0}},
                at=0,
                policies=Policies(after="lander-1"),
            )
        )
        deploy = reply.value["id"]
        await client.submit(Sync(robot="lru2", through=deploy))
        await client.submit(Sync(robot="lander"))
        await client.submit(Control(op="run", robot="lru2"))  # first: it must wait
        await client.wait_for(lambda m: skill(m, deploy).status == Status.SYNCHWAITING, 30.0)
        assert "after lander-1 on lander" in skill(client.mission, deploy).status_info
        await client.submit(Control(op="run", robot="lander"))
        await client.wait_for(lambda m: skill(m, deploy).status in FINISHED, 90.0)
        s, shelved = skill(client.mission, deploy), skill(client.mission, "lander-1")
        assert (shelved.status, s.status) == (Status.SUCCESS, Status.SUCCESS), s.status_info
        assert s.started_at >= shelved.finished_at
        shown = await asyncio.to_thread(ok, endpoint, "state", "lru2")
        assert "after lander-1" in next(ln for ln in shown.stdout.splitlines() if deploy in ln)
    finally:
        watch.close()
        await client.close()
