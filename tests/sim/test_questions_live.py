"""identify_stone asks (issue 29 item 4): finding nothing, the simulated
robot asks the operators whether to search wider; an answer "give up" fails
the skill saying so (its on_failure can act on it); unanswered, the default
(wider) applies on board at the timeout (3 sim-minutes: 3.6 s at speed 50)
and the robot searches wider. Over a delayed link (--link-delay, sim time)
an answer in time is taken; one arriving past the due changes nothing."""

from __future__ import annotations

from backend.core.model import FINISHED, CommandState, QuestionState, Status
from backend.core.ops import AddSkill, AnswerQuestion, Control, Sync

from .conftest import Stack, connect, skill

NOWHERE = {"x": 8.0, "y": -3.0}  # beside lru2's start (4, -3): no region within 16 m


async def _identify(client, label: str) -> str:
    reply = await client.submit(
        AddSkill(
            robot="lru2",
            skill="identify_stone",
            label=label,
            params={"target": NOWHERE, "search_radius": 6.0},
            at=0,
        )
    )
    sid = reply.value["id"]
    await client.submit(Sync(robot="lru2", through=sid))
    await client.submit(Control(op="run", robot="lru2"))
    return sid


def _asked_by(m, sid: str):
    return next((q for qs in m.questions.values() for q in qs if q.skill == sid), None)


async def test_identify_stone_asks_and_follows_the_answer_or_its_default(stack: Stack) -> None:
    client, watch = await connect(stack, speed=50, seed=1)
    try:
        gave_up = await _identify(client, "answered")
        m = await client.wait_for(lambda m: _asked_by(m, gave_up) is not None, 60.0)
        q = _asked_by(m, gave_up)
        assert "Search wider (12 m)?" in q.text and q.choices == ["wider", "give up"]
        assert (q.default, q.timeout_s) == ("wider", 180.0)
        await client.submit(AnswerQuestion(question=q.id, choice="give up"))
        m = await client.wait_for(lambda m: skill(m, gave_up).status in FINISHED, 60.0)
        s = skill(m, gave_up)
        assert (
            s.status == Status.FAILURE and "nothing to identify here; the operator" in s.status_info
        )
        assert "gave up" in s.status_info
        assert m.question(q.id).state == QuestionState.ANSWERED

        waited = await _identify(client, "unanswered")
        m = await client.wait_for(lambda m: skill(m, waited).status in FINISHED, 60.0)
        q = _asked_by(m, waited)
        assert (q.state, q.choice) == (QuestionState.DEFAULTED, "wider")
        s = skill(m, waited)
        assert s.status == Status.FAILURE and "nor within 12 m" in s.status_info
    finally:
        watch.close()
        await client.close()


async def test_over_a_delayed_link_an_answer_in_time_is_taken(stack: Stack) -> None:
    """30 sim-s each way (0.6 s at speed 50): the question and the answer
    cross the link well within the question's 3 sim-minutes."""
    client, watch = await connect(stack, speed=50, seed=1, extra=["--link-delay", "30s"])
    try:
        sid = await _identify(client, "delayed")
        m = await client.wait_for(lambda m: _asked_by(m, sid) is not None, 60.0)
        q = _asked_by(m, sid)
        assert q.is_open and q.asked < q.due
        await client.submit(AnswerQuestion(question=q.id, choice="give up"))
        m = await client.wait_for(lambda m: skill(m, sid).status in FINISHED, 60.0)
        assert skill(m, sid).status == Status.FAILURE and "gave up" in skill(m, sid).status_info
        assert m.question(q.id).state == QuestionState.ANSWERED
    finally:
        watch.close()
        await client.close()


async def test_an_answer_arriving_after_the_default_applied_is_refused_and_said(
    stack: Stack,
) -> None:
    """100 sim-s each way: the question reaches the ground after 100 s, the
    answer the robot after 200 s, past its 180 s: the robot took its default
    (wider) and searched on; the late answer changes nothing, and the ground
    says the default applied, not the answer."""
    client, watch = await connect(stack, speed=50, seed=1, extra=["--link-delay", "100s"])
    try:
        sid = await _identify(client, "late")
        m = await client.wait_for(lambda m: _asked_by(m, sid) is not None, 60.0)
        q = _asked_by(m, sid)
        reply = await client.submit(AnswerQuestion(question=q.id, choice="give up"))
        m = await client.wait_for(lambda m: skill(m, sid).status in FINISHED, 60.0)
        assert "nor within 12 m" in skill(m, sid).status_info  # it searched wider
        m = await client.wait_for(lambda m: not m.question(q.id).is_open, 60.0)
        ended = m.question(q.id)
        assert (ended.state, ended.choice) == (QuestionState.DEFAULTED, "wider")
        c = m.command(reply.value["command"])
        assert c is not None and c.state == CommandState.EXPIRED, c  # arrived past its due
    finally:
        watch.close()
        await client.close()
