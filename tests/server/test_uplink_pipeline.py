"""The pipelined uplink (issue 28): a new command leaves as soon as the link
allows, in sequence order, whatever earlier transmissions wait for; the
query timeout follows the robot's delay estimate.

The link's delay is injected by a raw robot that holds its receipts until
the test releases them (what a link D seconds long does for 2·D): nothing
here waits out a delay."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime, timedelta

import pytest

from backend.core.model import CommandState
from backend.core.ops import Cancel, Control, Sync
from backend.protocol.messages import Uplink
from backend.protocol.timing import RECEIPT_S, query_timeout_s
from backend.server import uplink

from .harness import RawRobot, serving

WAIT = 10.0  # upper bound of what takes milliseconds


class HeldReceipts(RawRobot):
    """A raw robot whose receipts wait until `release` is set (a long link);
    it records each transmission as it arrives: the seqs it carried."""

    def __init__(self, endpoint: str, name: str) -> None:
        super().__init__(endpoint, name)
        self.release = asyncio.Event()
        self.arrived: list[list[int]] = []
        self.cancels: list[list[int]] = []  # per transmission: the seqs it withdraws
        self.changed = asyncio.Event()

    async def _on_uplink(self, payload: bytes) -> bytes:
        commands = Uplink.model_validate_json(payload).commands
        self.arrived.append([e.seq for e in commands])
        self.cancels.append([e.seq for e in commands if e.cancel])
        self.changed.set()
        await self.release.wait()
        return super()._on_uplink(payload)

    async def until(self, predicate, what: str) -> None:
        async with asyncio.timeout(WAIT):
            while not predicate():
                self.changed.clear()
                await self.changed.wait()


def test_the_query_timeout_follows_the_one_way_delay():
    assert query_timeout_s(0.0) == RECEIPT_S == query_timeout_s(-1.0)
    assert query_timeout_s(6.0) == RECEIPT_S + 18.0  # main gave up after 5 s
    assert query_timeout_s(1200.0) > 2 * 1200  # Mars: longer than the round trip


async def test_a_new_command_leaves_while_the_last_one_waits_for_its_receipt(tmp_path):
    """Main sent one transmission at a time: a run issued right after a sync
    waited for the sync's receipt (or its 5 s timeout) before it left."""
    async with serving(tmp_path / "m.db") as (server, client):
        robot = HeldReceipts(client.endpoints[0], "lru1")
        try:
            robot.release.set()
            await robot.register("lru_science")
            robot.release.clear()  # from now on the link is long
            sync = await client.submit(Sync(robot="lru1"))
            await robot.until(lambda: robot.arrived == [[1]], "the sync")
            run = await client.submit(Control(op="run", robot="lru1"))
            # on the robot while the sync's receipt is still on its way back,
            # after the sync, in one transmission with it
            await robot.until(lambda: len(robot.arrived) == 2, "the run")
            assert robot.arrived == [[1], [1, 2]]
            sender = server.robot_link.senders["lru1"]
            assert len(sender._sending) == 2  # both transmissions under way
            assert server.engine.transmitting == {1, 2}
            assert [c.state for c in server.mission.uplink["lru1"]] == [CommandState.QUEUED] * 2
            robot.release.set()
            done = [await client.wait_command(sync.value["command"], WAIT)]
            done.append(await client.wait_command(run.value["commands"]["lru1"], WAIT))
            assert [c.state for c in done] == [CommandState.ACKED] * 2
            assert [e.seq for e in robot.received] == [1, 2]  # each applied once, in order
            # (the answers may be in before the receipts)
            await asyncio.wait_for(asyncio.gather(*list(sender._sending)), WAIT)
            assert server.engine.transmitting == set()
        finally:
            robot.release.set()
            robot.close()


async def test_a_cancel_leaves_at_once_while_the_command_waits_for_its_receipt(tmp_path):
    async with serving(tmp_path / "m.db") as (server, client):
        robot = HeldReceipts(client.endpoints[0], "lru1")
        try:
            robot.release.set()
            await robot.register("lru_science")
            robot.release.clear()
            sync = await client.submit(Sync(robot="lru1"))
            await robot.until(lambda: len(robot.arrived) == 1, "the sync")
            await client.submit(Cancel(command=sync.value["command"]))
            await robot.until(lambda: len(robot.arrived) == 2, "the cancel")
            assert robot.cancels == [[], [1]]
            assert len(server.robot_link.senders["lru1"]._sending) == 2
            robot.release.set()
            # the robot read the first transmission first: it applied the sync,
            # and its answer is the truth
            cmd = await client.wait_command(sync.value["command"], WAIT)
            assert cmd.state == CommandState.ACKED and cmd.cancel_requested
        finally:
            robot.release.set()
            robot.close()


async def test_the_sender_waits_for_a_receipt_as_long_as_the_robots_delay_says(
    tmp_path, monkeypatch
):
    """The robot's messages say it is 4 s away: its transmissions wait
    query_timeout_s(4) for a receipt, not main's fixed 5 s."""
    timeouts: list[float] = []
    real = uplink.query_all

    async def spy(session, key, payload, timeout):
        timeouts.append(timeout)
        return await real(session, key, payload, timeout)

    monkeypatch.setattr(uplink, "query_all", spy)
    async with serving(tmp_path / "m.db") as (server, client):
        robot = RawRobot(client.endpoints[0], "lru1")
        try:
            await robot.register("lru_science", sent=datetime.now(UTC) - timedelta(seconds=4))
            delay = server.robot_link.delay_of("lru1")
            assert delay == pytest.approx(4.0, abs=0.5)
            done = await client.submit(Sync(robot="lru1"))
            await client.wait_command(done.value["command"], WAIT)
            assert timeouts[0] == pytest.approx(query_timeout_s(delay))
            assert timeouts[0] > 2 * 4.0 + RECEIPT_S
        finally:
            robot.close()
