"""identify_stone asks (issue 29 item 4): finding nothing, the simulated
robot asks the operators whether to search wider; an answer "give up" fails
the skill saying so (its on_failure can act on it); unanswered, the default
(wider) applies on board at the timeout (3 sim-minutes: 3.6 s at speed 50)
and the robot searches wider."""

from __future__ import annotations

from backend.core.model import FINISHED, QuestionState, Status
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
