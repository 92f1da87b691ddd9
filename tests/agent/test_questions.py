"""A handler asks the operators (ctx.ask_operator): the question goes down
the downlink like a report, the answer comes up the uplink as a command; at
the timeout (mission time: the agent's time scale) the default applies and
the robot says so; a stop withdraws it. Nothing waits on a sleep: waits are
on the fake server's state, and mission minutes are fractions of a second."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from backend.agent import RobotAgent
from backend.core.model import QuestionAnswer, Status
from backend.core.ops import Ask, AskEnded
from backend.protocol.messages import Pause, Run, Stop

from .conftest import Harness, skill

S = Status


def asker(
    h: Harness,
    name: str,
    got: dict[str, Any],
    timeout: str = "10m",
    gate: asyncio.Event | None = None,
) -> RobotAgent:
    """A robot whose `search` asks whether to search wider (once `gate` is set),
    and says what it got."""
    a = h.agent(name)

    @a.skill("search", version="1.0.0")
    async def search(ctx):
        if gate is not None:
            await gate.wait()
        reply = await ctx.ask_operator(
            "Nothing found: search wider?", ["wider", "give up"], "wider", timeout
        )
        got["reply"] = reply
        return reply.choice == "wider"

    @a.skill("bad", version="1.0.0")
    async def bad(ctx):
        await ctx.ask_operator("which?", ["a", "b"], "c", 60)

    return a


def asks(h: Harness, robot: str) -> list[Ask]:
    return [m for m in h.server.asks.get(robot, []) if isinstance(m, Ask)]


def ended(h: Harness, robot: str) -> list[AskEnded]:
    return [m for m in h.server.asks.get(robot, []) if isinstance(m, AskEnded)]


def answer(q: Ask, choice: str) -> QuestionAnswer:
    return QuestionAnswer(question=1, ref=q.ref, choice=choice, by="ann@console")


async def test_an_answer_reaches_the_waiting_handler(harness: Harness) -> None:
    async with harness as h:
        lru = h.name("lru1")
        got: dict[str, Any] = {}
        a = asker(h, lru, got)
        await h.start(a)
        await h.run(lru, skill("q1", "search"))
        await h.until(lambda: bool(asks(h, lru)), what="the question")
        (q,) = asks(h, lru)
        assert (q.skill, q.choices, q.default, q.timeout_s) == (
            "q1",
            ["wider", "give up"],
            "wider",
            600,
        )
        assert a.questions.asking == [q.ref]
        reply = await h.server.command(lru, answer(q, "give up"))
        assert reply.ok and "give up" in reply.reason
        await h.until(lambda: h.server.has(lru, "q1", S.FAILURE), what="q1 ends")
        assert got["reply"].choice == "give up" and got["reply"].answered
        assert got["reply"].by == "ann@console"
        assert ended(h, lru) == [] and a.questions.asking == []
        # its order on the downlink: the question, the answer, then the skill's end
        assert q.seq < reply.answer.seq < h.server.applied[lru][-1].seq


async def test_the_default_applies_at_the_timeout_and_the_robot_says_so(harness: Harness) -> None:
    async with harness as h:
        lru = h.name("lru1")
        got: dict[str, Any] = {}
        a = asker(h, lru, got, timeout="5m")
        a.time_scale = 3000.0  # five mission minutes are 0.1 s
        await h.start(a)
        await h.run(lru, skill("q1", "search"))
        await h.until(lambda: h.server.has(lru, "q1", S.SUCCESS), what="q1 goes on with wider")
        assert got["reply"].choice == "wider" and not got["reply"].answered
        (q,) = asks(h, lru)
        assert (q.due - q.at).total_seconds() == 0.1
        (e,) = ended(h, lru)
        assert (e.ref, e.outcome, e.choice) == (q.ref, "default", "wider")
        late = await h.server.command(lru, answer(q, "give up"))
        assert not late.ok and "no longer asked: its default 'wider' applied" in late.reason


async def test_a_question_asked_out_of_range_arrives_and_is_answered_once_back(
    harness: Harness,
) -> None:
    async with harness as h:
        lru = h.name("lru1")
        got: dict[str, Any] = {}
        gate = asyncio.Event()
        a = asker(h, lru, got, gate=gate)
        await h.start(a)
        await h.run(lru, skill("q1", "search"))
        a.link.reachable = False
        gate.set()
        await h.until(
            lambda: any(isinstance(m, Ask) for m in a.pending_reports), what="asked aboard"
        )
        assert asks(h, lru) == []  # queued aboard while the link is cut
        a.link.reachable = True
        await h.until(lambda: bool(asks(h, lru)), what="the question after the link healed")
        reply = await h.server.command(lru, answer(asks(h, lru)[0], "wider"))
        assert reply.ok
        await h.until(lambda: h.server.has(lru, "q1", S.SUCCESS), what="q1 with the answer")
        assert got["reply"].answered


async def test_a_stop_withdraws_the_question(harness: Harness) -> None:
    async with harness as h:
        lru = h.name("lru1")
        got: dict[str, Any] = {}
        a = asker(h, lru, got)
        await h.start(a)
        await h.run(lru, skill("q1", "search"))
        await h.until(lambda: bool(asks(h, lru)), what="the question")
        await h.server.command(lru, Stop())
        await h.until(lambda: bool(ended(h, lru)), what="the withdrawal")
        (e,) = ended(h, lru)
        assert e.outcome == "withdrawn" and e.reason == "q1 was stopped"
        assert h.server.has(lru, "q1", S.IDLE_SYNCHRONIZED) and "reply" not in got
        assert a.questions.asking == []
        late = await h.server.command(lru, answer(asks(h, lru)[0], "wider"))
        assert not late.ok and "withdrawn (q1 was stopped)" in late.reason


async def test_a_pause_keeps_the_question_and_the_handler_goes_on_once_resumed(
    harness: Harness,
) -> None:
    async with harness as h:
        lru = h.name("lru1")
        a = h.agent(lru)
        returned = asyncio.Event()
        got: dict[str, Any] = {}

        @a.skill("search", version="1.0.0")
        async def search(ctx):
            got["reply"] = await ctx.ask_operator("wider?", ["wider", "give up"], "wider", "10m")
            returned.set()

        await h.start(a)
        await h.run(lru, skill("q1", "search"))
        await h.until(lambda: bool(asks(h, lru)), what="the question")
        (q,) = asks(h, lru)
        assert (await h.server.command(lru, Pause())).ok
        assert a.questions.asking == [q.ref]  # a pause does not withdraw it
        assert (await h.server.command(lru, answer(q, "give up"))).ok
        # taken, but the handler waits at its checkpoint while paused
        with pytest.raises(TimeoutError):
            await asyncio.wait_for(returned.wait(), 0.3)
        await h.server.command(lru, Run())
        await h.until(lambda: h.server.has(lru, "q1", S.SUCCESS), what="q1 goes on")
        assert got["reply"].choice == "give up" and got["reply"].answered
        assert ended(h, lru) == []  # answered: nothing withdrawn, no default


async def test_a_registration_lists_the_questions_still_asked(harness: Harness) -> None:
    async with harness as h:
        lru = h.name("lru1")
        a = asker(h, lru, {})
        await h.start(a)
        await h.run(lru, skill("q1", "search"))
        await h.until(lambda: bool(asks(h, lru)), what="the question")
        h.server.vanish()
        h.server.appear()
        await h.registered(lru, count=2)
        assert h.server.registrations_of(lru)[-1].asking == [asks(h, lru)[0].ref]


async def test_a_question_breaking_the_rules_fails_the_skill_saying_why(harness: Harness) -> None:
    async with harness as h:
        lru = h.name("lru1")
        a = asker(h, lru, {})
        await h.start(a)
        await h.run(lru, skill("b1", "bad"))
        await h.until(lambda: h.server.has(lru, "b1", S.FAILURE), what="b1 fails")
        info = h.server.applied[lru][-1].info
        assert "skill b1: ctx.ask_operator()" in info and "'c' is not one of the choices" in info
        assert asks(h, lru) == []  # nothing went down
        assert h.server.gaps == []  # and no downlink number was used up
