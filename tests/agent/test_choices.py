"""Places chosen on board (backend.agent.choices): a parameter bound to a
marker chosen on board gets its value from the robot's choice hook before
the handler runs; the report says the place; partners agree (the first
choice is told, the others take it without choosing)."""

from __future__ import annotations

import asyncio
from typing import Any

from backend.agent import Choice, RobotAgent, SkillFailed, choices
from backend.core.model import ChooseOnBoard, ChooseRule, Pose, SkillInstance, Status
from backend.protocol.messages import Enqueue, Run

from .conftest import Harness

S = Status
RULE = ChooseRule(pick="closest_pair", rank=1, place="approach", wait_s=600.0)


def go(sid: str) -> SkillInstance:
    """A skill whose goal the ground only estimates (0, 0)."""
    return SkillInstance(id=sid, skill="go", params={"goal": Pose().model_dump()}, status=S.IDLE)


def robot(h: Harness, name: str, got: list[Any]) -> RobotAgent:
    """`go` notes the goal its handler gets."""
    a = h.agent(name)
    a.time_scale = 1.0

    @a.skill("go", version="1.0.0")
    async def go_(ctx, goal: Pose):
        got.append(goal)
        return True

    return a


async def send(h: Harness, robot: str, sid: str, team: list[str], marker: str = "R1") -> None:
    choose = {sid: {"goal": ChooseOnBoard(marker=marker, rule=RULE, team=team)}}
    await h.server.command(
        robot, Enqueue(skills=[go(sid)], kinds={"go": {"goal": "pose"}}, choose=choose)
    )
    await h.server.command(robot, Run())


def chosen(h: Harness, robot: str, sid: str) -> dict[str, Pose]:
    out: dict[str, Pose] = {}
    for r in h.server.applied.get(robot, []):
        if r.id == sid:
            out.update(r.chosen)
    return out


async def test_the_hook_chooses_and_the_handler_gets_a_typed_pose(harness: Harness) -> None:
    async with harness as h:
        (lru1,) = h.names("lru1")
        got: list[Any] = []
        a = robot(h, lru1, got)
        asked: list[Choice] = []

        @a.on_choose
        def where(choice: Choice) -> Pose:
            asked.append(choice)
            return Pose(x=57.0, y=-38.0)

        await h.start(a)
        await send(h, lru1, "lru1-1", team=[])
        await h.until(lambda: h.server.has(lru1, "lru1-1", S.SUCCESS), what="go ran")
        assert got == [Pose(x=57.0, y=-38.0)]
        assert [(c.marker, c.param, c.skill, c.rule) for c in asked] == [("R1", "goal", "go", RULE)]
        assert asked[0].estimate == Pose()
        assert chosen(h, lru1, "lru1-1") == {"R1": Pose(x=57.0, y=-38.0)}
        assert h.server.has(lru1, "lru1-1", S.SYNCHWAITING, "R1 at (57.0, -38.0) (chosen here)")
        assert a.chosen == {"R1": Pose(x=57.0, y=-38.0)}


async def test_a_partner_takes_the_first_choice_without_choosing(harness: Harness) -> None:
    async with harness as h:
        lru1, lru2 = h.names("lru1", "lru2")
        got1: list[Any] = []
        got2: list[Any] = []
        a, b = robot(h, lru1, got1), robot(h, lru2, got2)
        a.on_choose(lambda choice: Pose(x=10.0, y=5.0))
        calls: list[str] = []

        @b.on_choose
        def other(choice: Choice) -> Pose:
            calls.append(choice.marker)
            return Pose(x=99.0, y=99.0)  # would disagree: never asked

        await h.start(a, b)
        await send(h, lru1, "lru1-1", team=[lru2])
        await h.until(lambda: h.server.has(lru1, "lru1-1", S.SUCCESS), what="lru1 went")
        assert b.chosen == {"R1": Pose(x=10.0, y=5.0)}  # told
        await send(h, lru2, "lru2-1", team=[lru1])
        await h.until(lambda: h.server.has(lru2, "lru2-1", S.SUCCESS), what="lru2 went")
        assert got2 == [Pose(x=10.0, y=5.0)] and not calls
        assert chosen(h, lru2, "lru2-1") == {"R1": Pose(x=10.0, y=5.0)}


async def test_an_undecided_partner_asks_before_choosing(harness: Harness) -> None:
    """lru2 starts first and waits (its hook does not know enough); lru1's
    choice reaches it by a tell, and it goes on with it."""
    async with harness as h:
        lru1, lru2 = h.names("lru1", "lru2")
        a, b = robot(h, lru1, []), robot(h, lru2, [])
        a.on_choose(lambda choice: Pose(x=3.0, y=4.0))
        b.on_choose(lambda choice: None)
        await h.start(a, b)
        await send(h, lru2, "lru2-1", team=[lru1])
        await h.until(
            lambda: h.server.has(lru2, "lru2-1", S.SYNCHWAITING, "choosing R1 on board"),
            what="lru2 waits to know enough",
        )
        await send(h, lru1, "lru1-1", team=[lru2])
        await h.until(lambda: h.server.has(lru2, "lru2-1", S.SUCCESS), what="lru2 went")
        assert chosen(h, lru2, "lru2-1") == {"R1": Pose(x=3.0, y=4.0)}
        assert h.server.has(lru2, "lru2-1", S.SYNCHWAITING, "(a partner's choice)")


async def test_without_a_hook_or_in_time_the_skill_fails_saying_why(
    harness: Harness, monkeypatch: Any
) -> None:
    monkeypatch.setattr(choices, "POLL_S", 0.01)
    async with harness as h:
        lru1, lru2 = h.names("lru1", "lru2")
        a, b = robot(h, lru1, []), robot(h, lru2, [])
        b.on_choose(lambda choice: None)
        await h.start(a, b)
        await send(h, lru1, "lru1-1", team=[])
        await h.until(lambda: h.server.has(lru1, "lru1-1", S.FAILURE), what="no hook")
        assert h.server.has(lru1, "lru1-1", S.FAILURE, "register one with agent.on_choose")
        short = ChooseRule(wait_s=0.05)
        cmd = {"lru2-1": {"goal": ChooseOnBoard(marker="R9", rule=short)}}
        await h.server.command(
            lru2, Enqueue(skills=[go("lru2-1")], kinds={"go": {"goal": "pose"}}, choose=cmd)
        )
        await h.server.command(lru2, Run())
        await h.until(lambda: h.server.has(lru2, "lru2-1", S.FAILURE), what="gave up")
        assert h.server.has(lru2, "lru2-1", S.FAILURE, "could not choose R9 on board within")


async def test_a_hook_that_gives_up_fails_the_skill(harness: Harness) -> None:
    async with harness as h:
        (lru1,) = h.names("lru1")
        a = robot(h, lru1, [])

        @a.on_choose
        async def nowhere(choice: Choice) -> Pose:
            await asyncio.sleep(0)
            raise SkillFailed("no region beyond the coverage is known")

        await h.start(a)
        await send(h, lru1, "lru1-1", team=[])
        await h.until(lambda: h.server.has(lru1, "lru1-1", S.FAILURE), what="gave up")
        assert h.server.has(lru1, "lru1-1", S.FAILURE, "no region beyond the coverage")
