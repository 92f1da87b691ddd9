"""Contingencies live: under a link delay, a drive whose goal is impassable
takes its on_failure branch on board (a goto, with the robot's own drive
skill), and ctl shows which branch ran and why. The delay is injected in sim
time (--link-delay at --speed), never waited out."""

from __future__ import annotations

import asyncio

from backend.core.model import Goto, Status
from backend.core.ops import Control, Sync

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
