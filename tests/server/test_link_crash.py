"""Crash: the server (a real process) is killed while commands are queued,
sent and answered; after the restart every command is in the state it had,
and each reaches its robot once.

The robots are wire-level robots in the test process (harness.RawRobot):
they record every command they process, and each command is processed once
by its sequence number, so a command sent twice under two numbers would show.
"""

from __future__ import annotations

import asyncio

import pytest

from backend.client.client import MissionClient
from backend.client.events import ConnectionState
from backend.core.model import CommandState, Mission
from backend.core.ops import Sync
from backend.transport import QueryError, QueryTimeout, TransportError

from .harness import Cluster, RawRobot, status

pytestmark = pytest.mark.timeout(120)

WAIT = 30.0


def states(m: Mission) -> dict[int, str]:
    return {c.id: c.state.value for cmds in m.uplink.values() for c in cmds}


async def register_again(robot: RawRobot, rtype: str, queue: list[str]) -> None:
    """Register with the restarted server (its session reconnects by itself)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + WAIT
    while True:
        try:
            await robot.register(rtype, queue)
            return
        except (QueryError, QueryTimeout, TransportError, AssertionError):
            if loop.time() > deadline:
                raise
            await asyncio.sleep(0.2)  # the router is coming back: ask again


def test_server_killed_with_commands_queued_sent_and_acked(tmp_path):
    cluster = Cluster(tmp_path, "missions/tutorial.yaml")
    cluster.start_server()

    async def scenario() -> None:
        lru1 = RawRobot(cluster.endpoint, "lru1", session="lru1-run")
        lru2 = RawRobot(cluster.endpoint, "lru2", session="lru2-run")
        client = MissionClient(cluster.endpoint, client_id="crash")
        seen: list[str] = []
        client.add_listener(
            lambda e: seen.append(e.state) if isinstance(e, ConnectionState) else None
        )
        try:
            await client.connect()
            await lru1.register("lru_science")
            # command 1: acked (lru1 answers at once)
            c1 = (await client.submit(Sync(robot="lru1", through="lru1-1"))).value["command"]
            await client.wait_command(c1, WAIT)
            # command 2: sent, its answer held aboard
            lru1.hold = True
            c2 = (await client.submit(Sync(robot="lru1", through="lru1-2"))).value["command"]
            # command 3: queued, lru2 has not come yet
            c3 = (await client.submit(Sync(robot="lru2"))).value["command"]
            before = {c1: "acked", c2: "sent", c3: "queued"}
            await client.wait_for(lambda m: states(m) == before, WAIT)
            assert [e.id for e in lru1.received] == [c1, c2]

            cluster.server.kill()  # SIGKILL: nothing flushed on the way out
            cluster.start_server()
            await client.wait_for(
                lambda m: client.connected and "reconnecting" in seen and states(m) == before,
                WAIT,
            )  # the journal gave back every command as it was
            assert status(client.mission, "lru1-2") == "idle"  # uplinking, not on lru1 yet

            # lru1 comes back with its answer to command 2 in its registration
            lru1.hold = False
            await register_again(lru1, "lru_science", ["lru1-1", "lru1-2"])  # what it holds
            await lru2.register("lru_manipulator")
            for cid in (c2, c3):
                done = await client.wait_command(cid, WAIT)
                assert done.state == CommandState.ACKED, done
            m = client.mission
            assert states(m) == {c1: "acked", c2: "acked", c3: "acked"}
            # each command reached its robot once, in order, under one number
            assert [(e.id, e.seq) for e in lru1.received] == [(c1, 1), (c2, 2)]
            assert [(e.id, e.seq) for e in lru2.received] == [(c3, 1)]
            assert [s.status.value for s in m.tasks["lru1"]] == ["idle_synchronized"] * 2
            assert [s.status.value for s in m.tasks["lru2"]] == ["idle_synchronized"] * 2
            assert not lru1.outbox and not lru2.outbox  # every answer taken
        finally:
            await client.close()
            lru1.close()
            lru2.close()

    try:
        asyncio.run(asyncio.wait_for(scenario(), 100))
    finally:
        cluster.stop()
