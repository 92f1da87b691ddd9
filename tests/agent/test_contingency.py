"""Contingencies on board (backend.agent.contingency): each branch taken
without a round trip, reported with its reason. Time is mission time: the
agents run at a high time scale (sim speed), so a mission minute is a
fraction of a wall second; nothing waits on a sleep."""

from __future__ import annotations

import asyncio

from backend.agent import RobotAgent, SkillFailed
from backend.core.model import (
    Branches,
    Fallback,
    FallbackSkill,
    Goto,
    Policies,
    SkillInstance,
    Status,
    Taken,
)
from backend.protocol.messages import Enqueue, Run, Stop

from .conftest import Harness

S = Status
SPEED = 600.0  # one mission minute is 0.1 s


def planned(sid: str, name: str, **policies: object) -> SkillInstance:
    return SkillInstance(id=sid, skill=name, status=S.IDLE, policies=Policies(**policies))


def rover(h: Harness, name: str, seen: dict[str, str | None]) -> RobotAgent:
    """A robot whose `stuck` fails, `slow` outlasts any timeout (noting why it
    was cancelled), `ok` succeeds and `drive_to` / `recharge` note their goal."""
    a = h.agent(name)
    a.time_scale = SPEED

    @a.skill("stuck", version="1.0.0")
    async def stuck(ctx):
        raise SkillFailed("wheel stuck in sand")

    @a.skill("slow", version="1.0.0")
    async def slow(ctx):
        try:
            await ctx.sleep(10 * 3600)
        finally:
            seen["slow"] = ctx.cancelled_because

    @a.skill("ok", version="1.0.0")
    async def ok(ctx):
        return True

    @a.skill("drive_to", version="1.0.0")
    async def drive_to(ctx, goal):
        seen["drive_to"] = f"{goal.x:g},{goal.y:g} for {ctx.skill.label}"

    return a


async def with_branch(
    h: Harness, robot: str, skills: list[SkillInstance], branches: Branches
) -> None:
    """Queue `skills`, the first with `branches` (drive_to skills), as a sync sends them."""
    kinds = {"drive_to": {"goal": "pose"}}
    contingencies = {skills[0].id: branches}
    await h.server.command(robot, Enqueue(skills=skills, contingencies=contingencies, kinds=kinds))


def branch_of(h: Harness, robot: str, sid: str, status: Status) -> Taken | None:
    found = [r for r in h.server.applied.get(robot, []) if r.id == sid and r.status == status]
    return found[-1].branch if found else None


async def test_skip_goes_on_and_halt_stops_the_queue(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = rover(h, lru1, {})
        await h.start(a)
        await h.server.enqueue(
            lru1,
            planned("s1", "stuck", on_failure="skip"),
            planned("s2", "ok"),
            planned("s3", "stuck"),
            planned("s4", "ok"),
        )
        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "s3", S.FAILURE), what="s3 failure")
        assert branch_of(h, lru1, "s1", S.FAILURE) == Taken(
            trigger="failure", branch="skip", reason="wheel stuck in sand"
        )
        assert h.server.has(lru1, "s1", S.FAILURE, "wheel stuck in sand → skip")
        assert h.server.has(lru1, "s2", S.SUCCESS)  # no operator step after s1
        # s3 has no contingency: it halts as before, and says no branch
        assert branch_of(h, lru1, "s3", S.FAILURE) == Taken(
            trigger="failure", branch="halt", reason="wheel stuck in sand"
        )
        assert a.queue == ["s4"] and a.active is None


async def test_timeout_cancels_the_handler_which_learns_why_then_skip(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        seen: dict[str, str | None] = {}
        a = rover(h, lru1, seen)
        await h.start(a)
        await h.server.enqueue(
            lru1, planned("t1", "slow", timeout="1m", on_timeout="skip"), planned("t2", "ok")
        )
        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "t2", S.SUCCESS), what="t2 after t1's timeout")
        taken = branch_of(h, lru1, "t1", S.FAILURE)
        assert taken is not None and (taken.trigger, taken.branch) == ("timeout", "skip")
        assert "1m" in taken.reason
        assert seen["slow"] == "timeout"


async def test_a_stop_is_told_apart_from_a_timeout(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        seen: dict[str, str | None] = {}
        a = rover(h, lru1, seen)
        await h.start(a)
        await h.server.enqueue(lru1, planned("t1", "slow", timeout="10h"))
        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "t1", S.RUNNING), what="t1 running")
        await h.server.command(lru1, Stop())
        await h.until(lambda: "slow" in seen, what="the handler ended")
        assert seen["slow"] == "stop"
        assert a.queue == ["t1"]  # back in the queue, no branch taken
        assert branch_of(h, lru1, "t1", S.IDLE_SYNCHRONIZED) is None


async def test_on_timeout_continue_lets_it_run_on_and_says_so(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = rover(h, lru1, {})
        release = asyncio.Event()

        @a.skill("wait", version="1.0.0")
        async def wait(ctx):
            await release.wait()

        await h.start(a)
        await h.server.enqueue(lru1, planned("w1", "wait", timeout="30s", on_timeout="continue"))
        await h.server.command(lru1, Run())
        await h.until(
            lambda: branch_of(h, lru1, "w1", S.RUNNING) is not None, what="over-time report"
        )
        taken = branch_of(h, lru1, "w1", S.RUNNING)
        assert taken is not None and taken.branch == "continue"
        release.set()
        await h.until(lambda: h.server.has(lru1, "w1", S.SUCCESS), what="w1 success")


async def test_fallback_runs_in_place_then_the_queue_goes_on(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        seen: dict[str, str | None] = {}
        a = rover(h, lru1, seen)
        await h.start(a)
        fallback = Fallback(fallback=[FallbackSkill(skill="drive_to")])
        f1 = planned("f1", "stuck", on_failure=fallback)
        run = SkillInstance(
            id="f1-f1", skill="drive_to", label="on failure of f1", params={"goal": {"x": 3}}
        )
        await with_branch(h, lru1, [f1, planned("f2", "ok")], Branches(on_failure=[run]))
        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "f2", S.SUCCESS), what="f2 after the fallback")
        assert seen["drive_to"] == "3,0 for on failure of f1"  # typed by its kind: a Pose
        trail = [(r.id, r.status, r.branch and r.branch.branch) for r in h.server.applied[lru1]]
        assert trail[:3] == [
            ("f1", S.RUNNING, None),
            ("f1", S.RUNNING, "fallback"),
            ("f1", S.FAILURE, "fallback"),
        ]
        assert h.server.has(lru1, "f1", S.FAILURE, "wheel stuck in sand → fallback: drive_to done")


async def test_goto_drives_to_the_marker_then_halts(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        seen: dict[str, str | None] = {}
        a = rover(h, lru1, seen)
        await h.start(a)
        g1 = planned("g1", "slow", timeout="2m", on_timeout=Goto(goto="Lander"))
        run = SkillInstance(id="g1-t1", skill="drive_to", params={"goal": {"x": 1, "y": 2}})
        await with_branch(h, lru1, [g1, planned("g2", "ok")], Branches(on_timeout=[run]))
        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "g1", S.FAILURE), what="g1 failure")
        taken = branch_of(h, lru1, "g1", S.FAILURE)
        assert taken is not None and (taken.trigger, taken.branch) == ("timeout", "goto")
        assert seen["drive_to"] is not None and seen["drive_to"].startswith("1,2")
        assert "to Lander" in h.server.applied[lru1][-1].info
        assert a.queue == ["g2"] and a.active is None  # halted at the rally point


async def test_past_its_deadline_a_skill_never_starts(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = rover(h, lru1, {})
        a.mission_time = lambda: 1000.0  # sim 0:16:40
        await h.start(a)
        await h.server.enqueue(
            lru1, planned("d1", "stuck", not_after=600, on_timeout="skip"), planned("d2", "ok")
        )
        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "d2", S.SUCCESS), what="d2")
        assert [r.status for r in h.server.applied[lru1] if r.id == "d1"] == [S.FAILURE]
        assert "not_after sim 0:10:00" in h.server.applied[lru1][0].info


async def test_a_barrier_timeout_starts_alone_or_halts(harness: Harness) -> None:
    from backend.core.model import BarrierInfo

    async with harness as h:
        lru1, lru2 = h.names("lru1", "lru2")  # lru2 never comes
        a = rover(h, lru1, {})
        await h.start(a)
        alone = BarrierInfo(
            barrier="b1", partners={lru2: "x1"}, timeout="1m", on_timeout="continue"
        )
        halt = BarrierInfo(barrier="b2", partners={lru2: "x2"}, timeout="1m")
        await h.server.command(
            lru1,
            Enqueue(
                skills=[planned("b1", "ok"), planned("b2", "ok"), planned("b3", "ok")],
                barriers={"b1": alone, "b2": halt},
            ),
        )
        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "b2", S.FAILURE), what="b2 gives up")
        assert h.server.has(lru1, "b1", S.SUCCESS)  # started alone
        started = branch_of(h, lru1, "b1", S.RUNNING)
        assert started is not None and (started.trigger, started.branch) == ("timeout", "continue")
        gave_up = branch_of(h, lru1, "b2", S.FAILURE)
        assert gave_up is not None and gave_up.branch == "halt"
        assert "partners not ready after 1m" in gave_up.reason
        assert a.queue == ["b3"]  # halted


async def test_after_waits_for_the_other_robots_success_or_takes_on_failure(
    harness: Harness,
) -> None:
    async with harness as h:
        lander, lru2 = h.names("lander", "lru2")
        a, b = rover(h, lander, {}), rover(h, lru2, {})
        await h.start(a, b)
        # lru2's deploy waits for the lander's shelve; its second skill for a failing one
        deploy = planned("deploy", "ok", after="shelve")
        doomed = planned("doomed", "ok", after="broken", on_failure="skip")
        await h.server.command(
            lru2,
            Enqueue(
                skills=[deploy, doomed, planned("last", "ok")],
                after={"deploy": lander, "doomed": lander},
            ),
        )
        await h.server.command(lru2, Run())
        await h.until(
            lambda: h.server.has(
                lru2, "deploy", S.SYNCHWAITING, f"after shelve on {lander}: unknown"
            ),
            what="deploy waits",
        )
        await h.server.enqueue(lander, planned("shelve", "ok"), planned("broken", "stuck"))
        await h.server.command(lander, Run())
        await h.until(lambda: h.server.has(lru2, "last", S.SUCCESS), what="lru2 done")
        assert h.server.has(lander, "shelve", S.SUCCESS)
        assert h.server.has(lru2, "deploy", S.SUCCESS)
        taken = branch_of(h, lru2, "doomed", S.FAILURE)
        assert taken is not None and taken.branch == "skip"
        assert taken.reason == f"after broken: it failed on {lander}"
        # deploy started only after shelve had succeeded
        shelved = next(
            r.at for r in h.server.applied[lander] if r.id == "shelve" and r.status == S.SUCCESS
        )
        started = next(
            r.at for r in h.server.applied[lru2] if r.id == "deploy" and r.status == S.RUNNING
        )
        assert started >= shelved
