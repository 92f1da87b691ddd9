"""`ctl questions` and `ctl answer` against a real server (issue 29): a
robot agent (in this process) asks; each ctl step is its own process; the
answer reaches the handler through the robot's uplink."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from backend.agent import RobotAgent
from backend.core.ops import Ask

from .helpers import Server, ctl, ok, ok_json


@pytest.fixture
def server(tmp_path):
    s = Server(tmp_path)
    try:
        yield s
    finally:
        s.stop()


async def run(*args: Any) -> Any:
    return await asyncio.to_thread(*args)


async def test_questions_lists_and_answer_answers(server) -> None:
    endpoint = server.endpoint
    got: dict[str, Any] = {}
    asked = asyncio.Event()
    agent = RobotAgent("lru1", "lru_science", connect=[endpoint], request_timeout=10)
    agent.question_listeners.append(lambda m: asked.set() if isinstance(m, Ask) else None)

    @agent.skill("drive_to", version="1.0.0")
    async def drive_to(ctx, **params):
        reply = await ctx.ask_operator("Sand ahead: go on?", ["go on", "turn back"], "go on", "1h")
        got["reply"] = reply
        return reply.choice == "go on"

    await agent.start()
    try:
        await agent.wait_registered(20)
        assert (await run(ok, endpoint, "questions")).stdout.strip() == "no open questions"
        await run(ok, endpoint, "sync", "lru1", "--through", "lru1-1", "--wait", "20")
        await run(ok, endpoint, "run", "lru1", "--wait", "20")
        await asyncio.wait_for(asked.wait(), 20)
        await agent.wait_acknowledged(20)  # the server has it

        listed = (await run(ok_json, endpoint, "questions"))["questions"]
        (q,) = listed
        assert (q["id"], q["robot"], q["skill"], q["state"]) == (1, "lru1", "lru1-1", "open")
        assert 3500 < q["default_in_s"] <= 3600 and q["answer_command"] is None
        text = (await run(ok, endpoint, "questions", "lru1")).stdout
        assert "question 1 lru1 (lru1-1): Sand ahead: go on?" in text
        assert "  1. go on\n  2. turn back" in text
        assert "its default 'go on' applies in 59 min" in text

        bad = await run(ctl, endpoint, "answer", "1", "3")
        assert bad.returncode == 2 and "choices 1 to 2, not 3" in bad.stderr
        wrong = await run(ctl, endpoint, "answer", "1", "maybe")
        assert wrong.returncode == 1 and "offers go on, turn back, not 'maybe'" in wrong.stderr
        none = await run(ctl, endpoint, "answer", "7", "go on")
        assert none.returncode == 1 and "no question 7" in none.stderr

        done = await run(ok, endpoint, "answer", "1", "2", "--wait", "20")
        lines = done.stdout.strip().splitlines()
        assert lines[0].startswith("queued for lru1, command ") and "answer 'turn back'" in lines[0]
        assert " applied by lru1" in lines[1]
        assert got["reply"].choice == "turn back" and got["reply"].by == "ctl-test"

        again = await run(ctl, endpoint, "answer", "1", "go on", "--json")
        assert again.returncode == 1 and '"code": "question_closed"' in again.stdout
        assert (await run(ok, endpoint, "questions")).stdout.strip() == "no open questions"
    finally:
        await agent.stop()


def test_watch_says_what_happened_to_a_question() -> None:
    from datetime import UTC, datetime

    from backend.cli.ctl.render import watch_line
    from backend.core import events as ev
    from backend.core.model import Question, QuestionState

    t = datetime(2030, 1, 1, tzinfo=UTC)
    q = Question(
        id=3,
        robot="lru2",
        ref="r-1",
        skill="lru2-4",
        text="search wider?",
        choices=["wider", "give up"],
        default="wider",
        timeout_s=300,
        asked=t,
        due=t,
    )
    batches = [
        ev.EventBatch(revision=5, events=[ev.QuestionAsked(question=q)], actor="lru2", op="ask"),
        ev.EventBatch(
            revision=6,
            events=[ev.QuestionAnswered(id=3, choice="give up", by="ann@c1", at=t, command=9)],
            actor="ann@c1",
            op="answer_question",
        ),
        ev.EventBatch(
            revision=7,
            events=[ev.QuestionClosed(id=3, state=QuestionState.DEFAULTED, choice="wider", at=t)],
            actor="lru2",
            op="ask_ended",
        ),
    ]
    lines = [watch_line("events", b, False) for b in batches]
    assert lines == [
        "r5 ask by lru2: question 3 from lru2 (lru2-4): search wider? [wider / give up; "
        "default wider]",
        "r6 answer_question by ann@c1: question 3 answered 'give up' by ann@c1 (command 9)",
        "r7 ask_ended by lru2: question 3 defaulted: wider",
    ]
