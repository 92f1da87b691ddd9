"""The robot link keeps every promise of docs/protocol.md, checked with a
hostile robot on a raw Zenoh session (no SDK): the cases issue 28 found on
main, each answered with a refusal that names what is wrong, after which the
robot's stream goes on."""

from __future__ import annotations

import json
from datetime import UTC, datetime

import pytest

from backend.agent import RobotAgent
from backend.core.model import CommandState, Dequeue, Status
from backend.core.ops import Answer, Control, Report, Sync
from backend.protocol.keys import Keys
from backend.protocol.messages import (
    ErrorReply,
    RegisterReply,
    Uplink,
    UplinkEntry,
    WorldMessage,
    dumps,
)
from backend.transport import QueryError, query

from .harness import RawRobot, serving

MAX_REPLY = 600  # bytes: a refusal is a sentence, never a dump of the message


async def refused(session, key: str, payload: bytes) -> ErrorReply:
    with pytest.raises(QueryError) as e:
        await query(session, key, payload, 10.0)
    raw = e.value.payload
    assert len(raw) < MAX_REPLY and b"internal error" not in raw, raw[:MAX_REPLY]
    return ErrorReply.model_validate_json(raw)


def without_zone(model, **times: str) -> bytes:
    """The model's JSON with times written without a zone."""
    data = json.loads(dumps(model))
    data.update(times)
    return json.dumps(data).encode()


async def test_times_without_a_zone_are_refused_naming_the_field(tmp_path):
    """Main answered `internal error ... can't subtract offset-naive and
    offset-aware datetimes`: a robot whose clock has no zone never delivered
    a report."""
    async with serving(tmp_path / "m.db") as (server, client):
        robot = RawRobot(client.endpoints[0], "lru1")
        try:
            naive = "2030-06-01T12:00:00"
            robot.rtype = "lru_science"
            err = await refused(
                robot.session,
                Keys.register("lru1"),
                without_zone(robot.registration(), sent=naive),
            )
            assert err.code == "bad_message" and err.robot == "lru1"
            assert "sent: Input should have timezone info" in err.message
            await robot.register("lru_science")  # with its zone: accepted
            report = robot.report("lru1-1", Status.RUNNING)  # not synchronized: refused
            dl = robot.downlink([report])
            err = await refused(robot.session, Keys.downlink("lru1"), without_zone(dl, sent=naive))
            assert err.code == "bad_message" and "sent: Input should have" in err.message
            bad_at = json.loads(dumps(dl))
            bad_at["messages"][0]["at"] = naive
            err = await refused(robot.session, Keys.downlink("lru1"), json.dumps(bad_at).encode())
            assert err.code == "bad_message" and "messages.0.report.at: Input" in err.message
            assert server.mission.report_seqs.get("lru1", 0) == 0  # nothing of them applied
            ack = await robot.flush()  # the same message, readable: its stream goes on
            assert ack.last_seq == 1 and [r.seq for r in ack.refused] == [1]
        finally:
            robot.close()


async def test_a_registration_says_only_what_the_ground_applied_or_refused(tmp_path):
    """Main answered a Register whose downlink held another robot's report
    `accepted, last_seq 15` while its own count stayed 14: the robot dropped
    message 15 and its next one waited forever (`missing: [15]`)."""
    async with serving(tmp_path / "m.db") as (server, client):
        robot = RawRobot(client.endpoints[0], "lru1")
        try:
            robot.seq = 1
            robot.outbox = [Report(robot="lru2", seq=1, id="lru2-1", status=Status.SUCCESS)]
            reply: RegisterReply = await robot.register("lru_science")
            assert reply.last_seq == 1 == server.mission.report_seqs["lru1"]
            [r] = reply.refused
            assert (r.seq, r.code) == (1, "bad_message")
            assert "lru1 cannot send messages of lru2" in r.message
            lru2 = server.mission.tasks["lru2"]
            assert "lru2" not in server.mission.report_seqs and lru2[0].status == Status.IDLE
            # the stream goes on: its next message, then one naming lru2 again
            robot.report("lru1-1", Status.RUNNING)  # refused by the rules (not queued)
            robot.seq += 1
            robot.outbox.append(Report(robot="lru2", seq=robot.seq, id="lru2-1", status="running"))
            ack = await robot.flush()
            assert (ack.last_seq, ack.missing) == (3, []) and server.mission.report_seqs[
                "lru1"
            ] == 3
            assert [(r.seq, r.code) for r in ack.refused] == [(2, "bad_report"), (3, "bad_message")]
            assert server.mission.tasks["lru2"][0].status == Status.IDLE
        finally:
            robot.close()


async def test_each_refused_message_is_listed_with_its_seq(tmp_path):
    """A report on a skill the mission does not have, an answer to a command
    never sent, running again at the same attempt: each is consumed, listed
    in `DownlinkAck.refused` with its seq and `bad_report`, and alerted."""
    async with serving(tmp_path / "m.db") as (server, client):
        robot = RawRobot(client.endpoints[0], "lru1")
        try:
            await robot.register("lru_science")
            done = await client.submit(Sync(robot="lru1", through="lru1-1"))
            await client.wait_command(done.value["command"], 10)
            done = await client.submit(Control(op="run", robot="lru1"))
            await client.wait_command(done.value["commands"]["lru1"], 10)
            robot.hold = True
            robot.report("lru1-1", Status.RUNNING)
            robot.report("lru1-1", Status.RUNNING)  # the same attempt again
            robot.report("nope-7", Status.RUNNING)
            robot.seq += 1
            robot.outbox.append(Answer(robot="lru1", seq=robot.seq, command=99, outcome="applied"))
            running = Report(robot="lru1", seq=robot.seq + 1, id="lru1-1", status="running")
            robot.seq += 1
            robot.outbox.append(running.model_copy(update={"attempt": 2}))  # a retry: applied
            first = robot.seq - 4
            ack = await robot.flush()
            assert ack.last_seq == robot.seq == server.mission.report_seqs["lru1"]
            assert [(r.seq, r.code) for r in ack.refused] == [
                (first + 1, "bad_report"),
                (first + 2, "bad_report"),
                (first + 3, "bad_report"),
            ]
            same, unknown, never = (r.message for r in ack.refused)
            assert "running -> running at the same attempt 1" in same
            assert "nope-7" in unknown and "command seq 99" in never
            s = server.mission.find("lru1-1")[2]
            assert (s.status, s.attempt) == (Status.RUNNING, 2)
        finally:
            robot.close()


async def test_an_agent_answers_what_it_cannot_read_with_a_sentence(tmp_path):
    """The simulated robots (the SDK's agent) answered an over-limit Uplink
    with `bad_message` and an over-limit WorldMessage with `bad_request` and
    a raw pydantic dump."""
    async with serving(tmp_path / "m.db") as (_, client):
        agent = RobotAgent("lru1", "lru_science", connect=client.endpoints, request_timeout=10)
        await agent.start()
        try:
            await agent.wait_registered(10)
            up = Uplink(
                robot="lru1",
                session=agent.session_id,
                commands=[UplinkEntry(seq=1, id=1, command=Dequeue(ids=["lru1-1"]))],
                sent=datetime.now(UTC),
            )
            big = dumps(up).replace(b'"lru1-1"', json.dumps("x" * 20_000).encode())
            err = await refused(client.session, Keys.uplink("lru1"), big)
            assert err.code == "limit_exceeded" and err.robot == "lru1"
            assert err.message.startswith("commands[0].command.ids[0]: 20,000 characters")
            assert "the uplink of lru1; nothing of it was applied" in err.message
            err = await refused(client.session, Keys.uplink("lru1"), b'{"robot": "lru1"}')
            assert err.code == "bad_message" and "the uplink of lru1 cannot be read" in err.message
            tell = WorldMessage(kind="tell", sender="lru2", topic="stone", data={"n": "s" * 20_000})
            err = await refused(client.session, Keys.world("lru1"), dumps(tell))
            assert err.code == "limit_exceeded" and err.message.startswith("data.n: 20,000")
            err = await refused(client.session, Keys.world("lru1"), b'{"kind": "shout"}')
            assert err.code == "bad_request" and "errors.pydantic.dev" not in err.message
            assert "a world message to lru1 cannot be read (kind:" in err.message
            assert agent._uplink.log.applied == 0  # nothing of them was processed
        finally:
            await agent.stop()


async def test_a_mirror_keeps_the_settled_commands_a_fresh_snapshot_has(tmp_path):
    """Settled commands leave `mission.uplink` (20 kept per robot) by the rule
    docs/protocol.md states: a client that applied every event and a fresh
    snapshot hold the same ones."""
    async with serving(tmp_path / "m.db") as (server, client):
        robot = RawRobot(client.endpoints[0], "lru1")
        try:
            await robot.register("lru_science")
            done = await client.submit(Sync(robot="lru1"))
            await client.wait_command(done.value["command"], 10)
            for _ in range(24):  # runs: each answered (acked) by the robot
                done = await client.submit(Control(op="run", robot="lru1"))
                cmd = await client.wait_command(done.value["commands"]["lru1"], 10)
                assert cmd.state == CommandState.ACKED
            mirrored = client.mission.uplink["lru1"]
            fresh = (await client.resync()).mission.uplink["lru1"]
            assert [c.id for c in mirrored] == [c.id for c in fresh] == list(range(6, 26))
            assert mirrored == fresh == server.mission.uplink["lru1"]
        finally:
            robot.close()
