"""A robot's downlink on the ground: its answers to commands and its reports
share one sequence, applied strictly in order, each once; a gap is never
skipped; a refused message uses up its number (alerted, journaled); only the
registered session of a robot is heard. The server runs in the test process;
the robot is `RawRobot` (protocol models, no SDK)."""

from __future__ import annotations

import asyncio

from backend.client.events import AlertRaised
from backend.core.model import Status
from backend.core.ops import Control, Sync
from backend.protocol.messages import ErrorReply
from backend.transport import QueryError

from .harness import RawRobot, serving, status

WAIT = 10.0


def scenario(test):
    """Run `test(server, client, robot, alerts)` with lru1 registered as a RawRobot."""

    async def main(tmp_path):
        async with serving(tmp_path / "m.db") as (server, client):
            robot = RawRobot(server.listen[0], "lru1")
            alerts: list = []
            client.add_listener(
                lambda e: alerts.append(e.alert) if isinstance(e, AlertRaised) else None
            )
            try:
                await robot.register("lru_science")
                await test(server, client, robot, alerts)
            finally:
                robot.close()

    return lambda tmp_path: asyncio.run(asyncio.wait_for(main(tmp_path), 60))


async def _synced(client, robot) -> None:
    await client.submit(Sync(robot="lru1", through="lru1-1"))
    await client.wait_for(lambda m: status(m, "lru1-1") == "idle_synchronized", WAIT)


@scenario
async def _gap(server, client, robot, alerts):
    await _synced(client, robot)  # the answer is downlink message 1
    robot.hold = True
    running = robot.report("lru1-1", Status.RUNNING)  # 2
    success = robot.report("lru1-1", Status.SUCCESS)  # 3
    ack = await robot.flush([success])  # 3 alone: 2 is missing
    assert (ack.last_seq, ack.missing) == (1, [2, 2])
    assert status(server.mission, "lru1-1") == "idle_synchronized"  # nothing skipped
    await client.wait_for(lambda m: any("not 2" in a.message for a in alerts), WAIT)
    ack = await robot.flush([success, running])  # both, out of order within the batch
    assert (ack.last_seq, ack.missing) == (3, [])
    assert status(server.mission, "lru1-1") == "success"
    again = await robot.flush([running, success])  # sent again: applied once
    assert again.last_seq == 3 and server.mission.report_seqs["lru1"] == 3


def test_a_message_past_a_gap_waits_for_the_missing_ones(tmp_path):
    _gap(tmp_path)


@scenario
async def _one_order(server, client, robot, alerts):
    robot.hold = True  # the robot answers, then reports; both go in one downlink
    await client.submit(Sync(robot="lru1", through="lru1-1"))
    await client.submit(Control(op="run", robot="lru1"))  # queued behind the sync
    await client.wait_for(lambda m: robot.transmissions > 0 and robot.applied == 2, WAIT)
    robot.report("lru1-1", Status.RUNNING)  # in run mode it starts the skill at once: 3
    robot.outbox.reverse()  # whatever order they travel in, the numbers decide
    ack = await robot.flush()
    assert ack.last_seq == 3 and ack.refused == []
    m = await client.wait_for(lambda m: status(m, "lru1-1") == "running", WAIT)
    assert [c.state.value for c in m.uplink["lru1"]] == ["acked", "acked"]
    assert not [a for a in alerts if a.level == "error"]


def test_an_answer_and_the_reports_after_it_are_applied_in_the_robots_order(tmp_path):
    _one_order(tmp_path)


@scenario
async def _refused(server, client, robot, alerts):
    await _synced(client, robot)
    bad = robot.report("lru1-1", Status.SUCCESS)  # queued -> success: not allowed
    good = robot.report("lru1-1", Status.RUNNING)
    ack = await robot.flush()
    assert ack.last_seq == good.seq and [r.code for r in ack.refused] == ["bad_report"]
    assert status(server.mission, "lru1-1") == "running"  # the sequence went on
    await client.wait_for(lambda m: any(f"report {bad.seq}" in a.message for a in alerts), WAIT)
    ops = [r.op for r in server.journal.records()]
    assert any('"downlink_refused"' in op for op in ops)  # journaled: replayed the same


def test_a_refused_message_uses_up_its_number(tmp_path):
    _refused(tmp_path)


@scenario
async def _stranger(server, client, robot, alerts):
    other = RawRobot(server.listen[0], "lru1", session="other")
    try:
        other.report("lru1-1", Status.RUNNING)
        try:
            await other.flush()
            raise AssertionError("a session that did not register was heard")
        except QueryError as e:
            err = ErrorReply.model_validate_json(e.payload)
        assert err.code == "not_registered" and err.robot == "lru1"
        assert "register first" in err.message
        assert status(server.mission, "lru1-1") == "idle"
    finally:
        other.close()


def test_only_the_registered_session_is_heard(tmp_path):
    _stranger(tmp_path)


@scenario
async def _once(server, client, robot, alerts):
    payload_op = Sync(robot="lru1", through="lru1-1")
    first = await client.submit(payload_op, request_id="s1")
    again = await client.submit(payload_op, request_id="s1")  # a retry of the same request
    assert again.duplicate and again.revision == first.revision
    await client.wait_command(first.value["command"], WAIT)
    # the server sends pending commands again until answered: applied once by seq
    sender = server.robot_link.senders["lru1"]
    sender.kick()
    await client.wait_for(lambda m: status(m, "lru1-1") == "idle_synchronized", WAIT)
    assert [e.seq for e in robot.received] == [1] and len(server.mission.uplink["lru1"]) == 1


def test_a_retried_request_queues_one_command_applied_once(tmp_path):
    _once(tmp_path)
