"""`after` robot to robot (backend.agent.precedence): the waiter is woken by
the other robot's outcome, not by polling; it says why the other robot does
not answer; a restarted robot still answers for skills it finished before.

The safety poll is set out of reach here (a day of mission time), so a test
passes only if the tell (or a presence change) woke the waiter."""

from __future__ import annotations

import pytest

from backend.agent import RobotAgent, precedence
from backend.core.model import Policies, SkillInstance, Status
from backend.protocol.messages import Enqueue, Run

from .conftest import Harness

S = Status


@pytest.fixture(autouse=True)
def no_safety_poll(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(precedence, "SAFETY_POLL_S", 86_400.0)


def planned(sid: str, name: str = "ok", **policies: object) -> SkillInstance:
    return SkillInstance(id=sid, skill=name, status=S.IDLE, policies=Policies(**policies))


def robot(h: Harness, name: str) -> RobotAgent:
    """`ok` succeeds; `hold` waits until the test lets it go (`robot.go`)."""
    a = h.agent(name)
    a.time_scale = 1.0  # mission time is wall time: a poll would be slow

    @a.skill("ok", version="1.0.0")
    async def ok(ctx):
        return True

    @a.skill("hold", version="1.0.0")
    async def hold(ctx):
        while not getattr(a, "go", False):
            await ctx.sleep(0.02)
        return True

    return a


async def wait_after(h: Harness, waiter: str, sid: str, partner: str, after: str) -> None:
    await h.server.command(
        waiter, Enqueue(skills=[planned(sid, after=after)], after={sid: partner})
    )
    await h.server.command(waiter, Run())


async def test_the_waiter_is_woken_by_the_other_robots_outcome(harness: Harness) -> None:
    async with harness as h:
        lander, lru2 = h.names("lander", "lru2")
        a, b = robot(h, lander), robot(h, lru2)
        await h.start(a, b)
        await h.run(lander, planned("shelve", "hold"))
        await h.until(lambda: h.server.has(lander, "shelve", S.RUNNING), what="shelving")
        await wait_after(h, lru2, "deploy", lander, "shelve")
        await h.until(
            lambda: h.server.has(lru2, "deploy", S.SYNCHWAITING, f"after shelve on {lander}"),
            what="deploy waits",
        )
        asked = b.world_stats["asks_sent"]
        a.go = True  # type: ignore[attr-defined]
        await h.until(lambda: h.server.has(lru2, "deploy", S.SUCCESS), what="deploy ran")
        # one ask to learn it ended (after the tell), none while it waited
        assert b.world_stats["asks_sent"] - asked <= 1
        assert a.world_stats["tells_sent"] == 1 and b.world_stats["tells_received"] == 1
        shelved = next(r.at for r in h.server.applied[lander] if r.status == S.SUCCESS)
        started = next(
            r.at for r in h.server.applied[lru2] if r.id == "deploy" and r.status == S.RUNNING
        )
        assert started >= shelved


async def test_the_waiter_says_the_other_robot_is_offline_then_goes_on(harness: Harness) -> None:
    async with harness as h:
        lander, lru2 = h.names("lander", "lru2")
        b = robot(h, lru2)
        await h.start(b)
        await wait_after(h, lru2, "deploy", lander, "shelve")
        await h.until(
            lambda: h.server.has(lru2, "deploy", S.SYNCHWAITING, f"{lander} offline"),
            what="the lander said offline",
        )
        a = robot(h, lander)  # it comes online: its presence wakes the waiter
        await h.start(a)
        await h.until(
            lambda: h.server.has(
                lru2, "deploy", S.SYNCHWAITING, f"after shelve on {lander}: unknown"
            ),
            what="asked again once the lander was there",
        )
        await h.run(lander, planned("shelve"))
        await h.until(lambda: h.server.has(lru2, "deploy", S.SUCCESS), what="deploy ran")


async def test_the_waiter_says_the_other_robot_is_out_of_reach(harness: Harness) -> None:
    async with harness as h:
        lander, lru2 = h.names("lander", "lru2")
        a, b = robot(h, lander), robot(h, lru2)
        reach = {"ok": False}
        b.link.can_reach = lambda other: reach["ok"]  # type: ignore[method-assign]
        await h.start(a, b)
        await h.run(lander, planned("shelve"))
        await h.until(lambda: h.server.has(lander, "shelve", S.SUCCESS), what="shelved")
        await wait_after(h, lru2, "deploy", lander, "shelve")
        await h.until(
            lambda: h.server.has(lru2, "deploy", S.SYNCHWAITING, f"{lander} unreachable"),
            what="unreachable",
        )
        reach["ok"] = True  # back within reach: asked again at once
        await h.until(lambda: h.server.has(lru2, "deploy", S.SUCCESS), what="deploy ran")


async def test_a_restarted_robot_answers_for_skills_it_finished_before(harness: Harness) -> None:
    async with harness as h:
        lander, lru2 = h.names("lander", "lru2")
        a, b = robot(h, lander), robot(h, lru2)
        await h.start(a, b)
        await h.run(lander, planned("shelve"))
        await h.until(lambda: h.server.has(lander, "shelve", S.SUCCESS), what="shelved")
        await a.stop()
        # the ground knows how it ended and says so when the new run registers
        h.server.outcomes[lander] = {"shelve": "success"}
        again = robot(h, lander)
        await h.start(again)
        await wait_after(h, lru2, "deploy", lander, "shelve")
        await h.until(lambda: h.server.has(lru2, "deploy", S.SUCCESS), what="deploy ran")
        assert not h.server.has(lru2, "deploy", S.SYNCHWAITING, "unknown")


async def test_a_restarted_robot_tells_a_waiter_once_it_learned(harness: Harness) -> None:
    """The waiter asked the new run before it registered ('unknown'): the run
    tells it once the ground said how the skill ended."""
    async with harness as h:
        lander, lru2 = h.names("lander", "lru2")
        b = robot(h, lru2)
        await h.start(b)
        h.server.refuse, h.server.refuse_code = "not yet", "unknown_robot"
        a = robot(h, lander)
        await a.start()  # online, not registered: it knows nothing of shelve
        await wait_after(h, lru2, "deploy", lander, "shelve")
        await h.until(
            lambda: h.server.has(lru2, "deploy", S.SYNCHWAITING, "unknown"), what="unknown"
        )
        h.server.refuse = None
        h.server.outcomes[lander] = {"shelve": "success"}
        h.server.vanish()
        h.server.appear()  # the robots register again; the lander learns
        await h.until(lambda: h.server.has(lru2, "deploy", S.SUCCESS), what="deploy ran")
        assert a.world_stats["tells_sent"] == 1
