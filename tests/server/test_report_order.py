"""A robot in run mode starts a skill as soon as it is enqueued and may report
it before its reply to the enqueue reaches the server. The server must apply
that report after the synchronization, not refuse it (the skill would stay
queued on the ground while it ran on the robot)."""

from __future__ import annotations

import asyncio
import inspect
from datetime import UTC, datetime

import zenoh
from zenoh.handlers import Callback

from backend.core.model import Status
from backend.core.ops import Report, Sync
from backend.protocol.keys import Keys
from backend.protocol.messages import CommandReply, ReportAck, ReportBatch, dumps

from .harness import RawRobot, drive, serving, status


class EagerRobot(RawRobot):
    """Answers an enqueue only after sending `running` for its first skill,
    like an agent whose handler started before the reply left. With
    `via_register`, the report rides on a new registration instead (a robot
    whose link dropped and came back while the enqueue was in flight)."""

    def __init__(self, endpoint: str, name: str, *, via_register: bool = False):
        self.seq = 0
        self.via_register = via_register
        super().__init__(endpoint, name)

    def answer(self, enqueued: list[str]) -> CommandReply:
        if enqueued:
            self.seq += 1
            report = Report(
                robot=self.name,
                seq=self.seq,
                id=enqueued[0],
                status=Status.RUNNING,
                at=datetime.now(UTC),
            )
            if self.via_register:
                key, payload = (
                    Keys.register(self.name),
                    dumps(self.registration(reports=[report], queue=enqueued)),
                )
            else:
                key, payload = Keys.reports(self.name), dumps(ReportBatch(reports=[report]))
            # sent (not awaited) before this reply: it reaches the server first
            self.session.get(
                key,
                Callback(lambda _reply: None, lambda: None, indirect=False),
                payload=payload,
                timeout=10.0,
                consolidation=zenoh.ConsolidationMode.NONE,
            )
        return CommandReply(ids=enqueued)


def test_a_report_sent_before_the_enqueue_reply_is_applied_after_the_sync(cluster):
    robot = EagerRobot(cluster.endpoint, "lru1")
    try:

        async def scenario(c):
            await robot.register("lru_science")  # online once registered
            reply = await c.submit(Sync(robot="lru1", through="lru1-1"))
            assert reply.value["synchronized"] == ["lru1-1"]
            m = await c.wait_for(lambda m: status(m, "lru1-1") == "running", 10)
            assert m.report_seqs["lru1"] == 1  # applied, not refused and consumed

        drive(cluster, scenario)
    finally:
        robot.close()


def test_a_registration_during_the_enqueue_waits_for_it(cluster):
    robot = EagerRobot(cluster.endpoint, "lru1", via_register=True)
    try:

        async def scenario(c):
            await robot.register("lru_science")
            reply = await c.submit(Sync(robot="lru1", through="lru1-1"))
            assert reply.value["synchronized"] == ["lru1-1"]
            m = await c.wait_for(lambda m: status(m, "lru1-1") == "running", 10)
            assert m.report_seqs["lru1"] == 1

        drive(cluster, scenario)
    finally:
        robot.close()


def test_a_batch_arriving_as_the_robots_turn_passes_on_waits_for_those_ahead(tmp_path):
    """A report batch is applied at once only when nobody holds or waits for
    the robot's turn. Just after a command's turn ends, the batches that
    waited for it go first: applied before them, a later batch's sequence
    numbers would make theirs duplicates, and their reports would be lost."""

    async def scenario() -> None:
        async with serving(tmp_path / "m.db") as (server, client):
            robot = RawRobot(server.listen[0], "lru1")
            try:
                await robot.register("lru_science")
                await client.submit(Sync(robot="lru1", through="lru1-1"))

                def batch(seq: int, status: Status) -> bytes:
                    return dumps(
                        ReportBatch(
                            reports=[
                                Report(
                                    robot="lru1",
                                    seq=seq,
                                    id="lru1-1",
                                    status=status,
                                    at=datetime.now(UTC),
                                )
                            ]
                        )
                    )

                key = Keys.reports("lru1")
                start = server.mission.revision
                turn = server.robot_link._turn("lru1")
                async with turn:  # as a command to lru1 in flight
                    waiting = [
                        server.robot_link._handle_reports(batch(1, Status.RUNNING), key),
                        server.robot_link._handle_reports(batch(2, Status.PAUSED), key),
                    ]
                    assert all(inspect.isawaitable(w) for w in waiting)
                    tasks = [asyncio.ensure_future(w) for w in waiting]
                    await asyncio.sleep(0)  # both now wait for the turn
                # the turn is released; its next waiter has not run yet
                late = server.robot_link._handle_reports(batch(3, Status.RUNNING), key)
                assert inspect.isawaitable(late)
                acks = await asyncio.gather(*tasks, late)
                assert [ReportAck.model_validate_json(a).refused for a in acks] == [[], [], []]
                statuses = [
                    e.changes["status"]
                    for r in server.journal.records(after=start)
                    for e in r.batch.events
                    if e.ev == "skill_changed"
                ]
                assert statuses == ["running", "paused", "running"]  # all three, in sequence order
                assert server.mission.report_seqs["lru1"] == 3
            finally:
                robot.close()

    asyncio.run(scenario())
