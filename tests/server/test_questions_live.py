"""Robots ask, end to end through the server: a real agent's question opens
in the mission and raises a `question` alert; an operator's answer travels
the uplink as a command and reaches the handler; a restarted server keeps
the open question from its journal and the answer still arrives."""

from __future__ import annotations

from typing import Any

from backend.agent import RobotAgent
from backend.client.client import MissionClient
from backend.client.events import AlertRaised
from backend.core.model import CommandState, QuestionState
from backend.core.ops import AnswerQuestion, Control, Sync
from backend.transport import free_port, loopback_endpoint

from .harness import new_server, serving, status, until


def asking_robot(endpoints: list[str], got: dict[str, Any]) -> RobotAgent:
    """lru1 whose drive_to asks whether to go on, and says what it got."""
    agent = RobotAgent("lru1", "lru_science", connect=endpoints, request_timeout=10)

    @agent.skill("drive_to", version="1.0.0")
    async def drive_to(ctx, **params):
        reply = await ctx.ask_operator("Sand ahead: go on?", ["go on", "turn back"], "go on", "1h")
        got["reply"] = reply
        return reply.choice == "go on"

    return agent


async def test_a_question_is_alerted_answered_and_taken_by_the_robot(tmp_path):
    async with serving(tmp_path / "m.db") as (server, client):
        alerts: list[Any] = []
        client.add_listener(
            lambda e: alerts.append(e.alert) if isinstance(e, AlertRaised) else None
        )
        got: dict[str, Any] = {}
        agent = asking_robot(client.endpoints, got)
        await agent.start()
        try:
            await agent.wait_registered(10)
            await client.submit(Sync(robot="lru1", through="lru1-1"))
            await client.submit(Control(op="run", robot="lru1"))
            await until(client, lambda m: bool(m.open_questions("lru1")))
            (q,) = client.mission.open_questions("lru1")
            assert (q.skill, q.choices, q.timeout_s) == ("lru1-1", ["go on", "turn back"], 3600)
            await until(client, lambda m: any(a.kind == "question" for a in alerts))
            (alert,) = [a for a in alerts if a.kind == "question"]
            assert alert.question == q.id and "Sand ahead: go on?" in alert.message
            reply = await client.submit(AnswerQuestion(question=q.id, choice="turn back"))
            assert reply.value["question"] == q.id
            await until(client, lambda m: status(m, "lru1-1") == "failure")
            answered = client.mission.question(q.id)
            assert (answered.state, answered.choice) == (QuestionState.ANSWERED, "turn back")
            assert answered.answered_by == "t"  # the client id, as the journal names it
            c = client.mission.command(reply.value["command"])
            assert c.state == CommandState.ACKED and c.op == "answer"
            assert got["reply"].choice == "turn back" and got["reply"].answered
        finally:
            await agent.stop()


async def test_a_restarted_server_keeps_the_open_question_and_its_answer_arrives(tmp_path):
    db = tmp_path / "m.db"
    endpoint = loopback_endpoint(free_port())
    got: dict[str, Any] = {}
    agent = asking_robot([endpoint], got)
    server = new_server(db, endpoint)
    await server.start()
    try:
        async with MissionClient(endpoint, client_id="t") as client:
            await agent.start()
            await agent.wait_registered(10)
            await client.submit(Sync(robot="lru1", through="lru1-1"))
            await client.submit(Control(op="run", robot="lru1"))
            await until(client, lambda m: bool(m.open_questions("lru1")))
        await server.stop()
        server = new_server(db, endpoint)
        await server.start()
        (q,) = server.mission.open_questions("lru1")  # from the journal
        async with MissionClient(endpoint, client_id="t2") as client:
            await until(client, lambda m: client.robots["lru1"].online)
            assert client.mission.question(q.id).is_open  # it still asks: not withdrawn
            await client.submit(AnswerQuestion(question=q.id, choice="go on"))
            await until(client, lambda m: status(m, "lru1-1") == "success")
            assert client.mission.question(q.id).state == QuestionState.ANSWERED
        assert got["reply"].by == "t2" and got["reply"].answered
    finally:
        await agent.stop()
        await server.stop()
