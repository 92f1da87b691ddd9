"""The robot SDK as an integrator meets it: mistakes in setting up an agent or
writing a handler get a sentence naming the robot, the skill or parameter and
what to do, never a bare TypeError or a silently broken robot."""

from __future__ import annotations

import asyncio
import logging
import threading

import pytest

from backend.agent import AlreadyConnected, RegistrationRefused, RobotAgent, SkillFailed, Success
from backend.core.library import SkillSignature
from backend.core.model import Pose
from backend.core.model import Status as S
from backend.protocol.messages import Pause, Run, Stop

from .conftest import Harness, skill


def test_connect_takes_one_endpoint_or_a_list_and_names_a_bad_one() -> None:
    assert RobotAgent("r1", "rover", connect="tcp/127.0.0.1:7447").connect == ["tcp/127.0.0.1:7447"]
    with pytest.raises(
        ValueError,
        match=r"robot r1: connect endpoint 'localhost:7447' is not PROTOCOL/ADDRESS, like tcp/",
    ):
        RobotAgent("r1", "rover", connect=["localhost:7447"])
    with pytest.raises(ValueError, match="robot r1: connect lists no endpoint"):
        RobotAgent("r1", "rover", connect=[])


def test_skill_registration_mistakes_are_refused_with_the_skill_named() -> None:
    a = RobotAgent("r1", "rover", connect="tcp/127.0.0.1:7447")
    with pytest.raises(TypeError, match="robot r1, skill scan: the handler must be a function"):
        a.add_skill("scan", "scan_handler")  # type: ignore[arg-type]
    with pytest.raises(
        TypeError,
        match=r"robot r1, skill scan: the handler must take the SkillContext .* def scan\(ctx",
    ):

        def scan() -> None: ...

        a.add_skill("scan", scan)
    with pytest.raises(ValueError, match="robot r1, skill scan: version '1.0' is not SemVer"):
        a.add_skill("scan", lambda ctx: None, version="1.0")
    with pytest.raises(
        TypeError, match=r'write @agent.skill\("NAME", version="1.0.0"\).* above \'drive\''
    ):

        @a.skill  # type: ignore[arg-type]
        def drive(ctx): ...

    @a.skill("scan", version="1.0.0")
    def first(ctx): ...

    with pytest.raises(
        ValueError, match=r"robot r1, skill scan: a handler is registered already \(first\)"
    ):
        a.add_skill("scan", lambda ctx: None)
    assert a.manifest().skills == {"scan": "1.0.0"}


async def test_skills_added_after_start_are_refused(harness: Harness) -> None:
    async with harness as h:
        a = h.agent(h.name("lru1"))
        await a.start()
        with pytest.raises(RuntimeError, match="skill late: register skills before start()"):
            a.add_skill("late", lambda ctx: None)


async def test_wait_registered_says_why(harness: Harness) -> None:
    async with harness as h:
        lru1, lru2 = h.names("lru1", "lru2")
        h.server.refuse = f"robot '{lru1}' is not part of this mission"
        a = h.agent(lru1)
        await a.start()
        with pytest.raises(
            RegistrationRefused,
            match=f"the mission server refused robot {lru1}: robot '{lru1}' is not part",
        ):
            await a.wait_registered(10)

        h.server.vanish()  # no server up: a timeout that says so
        b = h.agent(lru2)
        await b.start()
        with pytest.raises(
            TimeoutError,
            match=f"robot {lru2} not registered within 0.3 s: no mission server is up behind tcp/",
        ):
            await b.wait_registered(0.3)


async def test_registering_says_how_each_handler_differs_from_the_library(
    harness: Harness,
) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)
        h.server.signatures["drive_to"] = SkillSignature(
            params={"goal": "pose", "speed": "float", "tolerance": "float"},
            required=["goal"],
            defaults={"speed": 0.5, "tolerance": 0.5},
        )
        h.server.signatures["look"] = SkillSignature(params={"target": "pose"})

        @a.skill("drive_to")
        async def drive_to(ctx, goal, speed=0.7, heading=None):
            return None

        @a.skill("look")
        async def look(ctx, **params):  # takes whatever comes: nothing to compare
            return None

        await h.start(a)
        await a.wait_registered(5.0)  # the reply has been read
        where = f"robot {lru1}, skill drive_to: handler drive_to()"
        assert a.handler_problems == [
            f"{where} has no parameter 'tolerance' (float in the library): the skill fails when "
            "it runs; add it to the signature",
            f"{where} gives 'speed' a default (0.7) it never uses: the server always sends it "
            "(the library's default is 0.5); remove the default",
            f"{where} takes 'heading', which is not a parameter of drive_to in the library "
            "(goal, speed, tolerance): it never gets a value; remove it",
        ]


async def test_handler_signatures_that_do_not_fit_the_parameters_fail_with_a_reason(
    harness: Harness,
) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)

        @a.skill("drive_to")
        async def drive_to(ctx, goal):
            return None

        @a.skill("identify")
        def identify(ctx, target, partner):
            return None

        await h.start(a)
        await h.run(
            lru1,
            skill("d1", "drive_to", goal={"x": 1.0}, speed=0.5),
            skill("i1", "identify", target="stone"),
        )
        await h.until(lambda: h.server.has(lru1, "d1", S.FAILURE), what="d1 failure")
        assert h.server.applied[lru1][-1].info == (
            "handler drive_to() does not accept parameter 'speed' sent by the server: "
            "add it to its signature (or take **params)"
        )
        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "i1", S.FAILURE), what="i1 failure")
        assert h.server.applied[lru1][-1].info.startswith(
            "handler identify() needs parameter 'partner', which the server did not send"
        )
        assert h.server.applied[lru1][-1].info.endswith(
            "not a parameter of the skill in the library (sent: target); remove it from the "
            "signature"
        )


async def test_a_handler_bug_is_one_line_for_the_operator_and_a_traceback_in_the_log(
    harness: Harness, caplog: pytest.LogCaptureFixture
) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)

        @a.skill("work")
        def work(ctx):
            return {}["missing"]

        await h.start(a)
        await h.run(lru1, skill("w1"))
        await h.until(
            lambda: h.server.has(lru1, "w1", S.FAILURE, "KeyError: 'missing'"), what="w1 failure"
        )
        logged = [
            r
            for r in caplog.records
            if r.name == "backend.agent" and "the handler of w1 (work) raised" in r.getMessage()
        ]
        assert logged and logged[0].exc_info is not None


async def test_a_bad_telemetry_source_does_not_break_commands(
    harness: Harness, caplog: pytest.LogCaptureFixture
) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1, telemetry_hz=20.0)
        a.pose = lambda: (1.0, 2.0)  # type: ignore[assignment, return-value]
        a.link.quality = "good"  # type: ignore[assignment]

        @a.skill("work")
        async def work(ctx):
            return None

        await h.start(a)
        reply = await h.server.enqueue(lru1, skill("w1"))  # its reply carries telemetry-making code
        assert reply.ok
        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "w1", S.SUCCESS), what="w1 success")
        t = a.telemetry()
        assert (t.pose, t.link) == (Pose(), 0.0)
        said = [
            r.getMessage()
            for r in caplog.records
            if "telemetry sends a default instead" in r.getMessage()
        ]
        assert (
            len([m for m in said if "agent.pose() must return a backend.core.model.Pose" in m]) == 1
        )  # once
        assert len([m for m in said if "agent.link.quality must be a number" in m]) == 1


async def test_a_world_handler_that_fails_is_named_on_both_sides(
    harness: Harness, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="backend.agent")
    async with harness as h:
        lru1, lru2 = h.names("lru1", "lru2")
        a, b = h.agent(lru1), h.agent(lru2)
        a.on_ask("stone", lambda data, sender: data["id"])  # KeyError: the asker sent no id
        a.on_ask("rss", lambda data, sender: [1, 2])  # not a dict
        answers: dict[str, object] = {}

        @b.skill("fetch")
        async def fetch(ctx):
            answers["stone"] = await ctx.ask(lru1, "stone", {})
            answers["rss"] = await ctx.ask(lru1, "rss")

        await h.start(a, b)
        await h.run(lru2, skill("f1", "fetch"))
        await h.until(lambda: h.server.has(lru2, "f1", S.SUCCESS), what="fetch done")
        assert answers == {"stone": None, "rss": None}
        text = "\n".join(r.getMessage() for r in caplog.records)
        assert (
            f"{lru1} cannot answer ask 'stone' from {lru2}: its on_ask handler raised "
            "KeyError: 'id'" in text
        )
        assert (
            f"{lru1} cannot answer ask 'rss' from {lru2}: its on_ask handler returned a list; "
            "it must return a dict or None" in text
        )
        # the asker's log carries the same sentence, not a JSON blob
        assert f"{lru2}: ask {lru1}/rss failed: {lru1} cannot answer ask 'rss'" in text


def test_a_manifest_that_cannot_be_sent_is_refused_at_construction() -> None:
    def agent(**kw: object) -> RobotAgent:
        args: dict = {"name": "lru1", "robot_type": "rover", "connect": "tcp/127.0.0.1:7447", **kw}
        return RobotAgent(**args)

    with pytest.raises(
        ValueError, match=r"robot name 'lru 1' must start with a letter and hold only letters"
    ):
        agent(name="lru 1")
    with pytest.raises(ValueError, match=r"robot lru1: type 'rover/2' must start with a letter"):
        agent(robot_type="rover/2")
    with pytest.raises(
        ValueError, match=r"robot lru1: module nav version '2.1' is not SemVer \(like 2.1.0\)"
    ):
        agent(modules={"nav": "2.1"})
    with pytest.raises(
        ValueError,
        match=r"robot lru1: the manifest cannot be written as JSON "
        r"\(properties must be JSON values\)",
    ):
        agent(properties={"arm": object()})
    with pytest.raises(
        ValueError, match=r"robot lru1: skill name 'drive to' must start with a letter"
    ):
        agent().add_skill("drive to", lambda ctx: None)
    assert agent(modules={"nav": "2.1.0-rc1"}).manifest().modules[0].version == "2.1.0-rc1"


async def test_an_autonomous_retry_shows_in_ctx_skill_too(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)
        seen: list[tuple[int, int]] = []

        @a.skill("grasp")
        async def grasp(ctx):
            seen.append((ctx.attempt, ctx.skill.attempt))
            if ctx.attempt == 1:
                raise SkillFailed("slipped")

        await h.start(a)
        await h.run(lru1, skill("g1", "grasp", retries=1))
        await h.until(lambda: h.server.has(lru1, "g1", S.SUCCESS), what="success")
        assert seen == [(1, 1), (2, 2)]


async def test_ctx_check_in_a_coroutine_warns_once_that_it_ignores_the_pause(
    harness: Harness, caplog: pytest.LogCaptureFixture
) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)
        paused = asyncio.Event()
        checked = asyncio.Event()

        @a.skill("work")
        async def work(ctx):
            await paused.wait()
            ctx.check()
            ctx.check()
            checked.set()

        await h.start(a)
        await h.run(lru1, skill("w1"))
        await h.until(lambda: h.made(lru1, "w1", S.RUNNING), what="running")
        await h.server.command(lru1, Pause())
        paused.set()
        await asyncio.wait_for(checked.wait(), 10)
        said = [
            r for r in caplog.records if "calls ctx.check(), which cannot wait" in r.getMessage()
        ]
        assert len(said) == 1 and "use await ctx.checkpoint()" in said[0].getMessage()


async def test_a_second_agent_under_the_same_name_is_refused_at_start(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a, twin = h.agent(lru1), h.agent(lru1)
        await a.start()
        with pytest.raises(
            AlreadyConnected,
            match=f"robot {lru1} is already connected .* a hung one after its lease",
        ):
            await twin.start()
        assert twin._session is None  # closed again: nothing of it stays declared
        await a.stop()
        await twin.start()  # the first one is gone: the name is free
        await h.registered(lru1)


async def test_a_handler_may_stop_its_own_agent(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)
        returned = asyncio.Event()

        @a.skill("shutdown")
        async def shutdown(ctx):
            await a.stop()  # e.g. an emergency: the robot leaves the mission
            returned.set()

        await h.start(a)
        await h.run(lru1, skill("x1", "shutdown"))
        await asyncio.wait_for(returned.wait(), 10)  # stop() was not cancelled half-way
        assert a._session is None  # the session is closed: the process can exit


def test_world_handlers_are_registered_once_and_must_be_callable() -> None:
    a = RobotAgent("r1", "rover", connect="tcp/127.0.0.1:7447")
    a.on_ask("stone", lambda data, sender: None)
    with pytest.raises(
        ValueError, match="robot r1, on_ask 'stone': a handler is registered already"
    ):
        a.on_ask("stone", lambda data, sender: None)
    with pytest.raises(
        TypeError,
        match=r"robot r1, on_tell 'box': the handler must be a function fn\(data, sender\)",
    ):
        a.on_tell("box", {"x": 1})  # type: ignore[arg-type]


async def test_odd_values_from_a_handler_reach_the_operator_as_text(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)

        @a.skill("count")
        async def count(ctx):
            ctx.progress(0.5, 42, eta_s=3)  # info and ETA go into telemetry, which checks types
            assert a.telemetry().info == "42"
            return Success(7)

        @a.skill("fail")
        async def fail(ctx):
            raise SkillFailed(ValueError("arm fault 3"))  # type: ignore[arg-type]

        await h.start(a)
        await h.run(lru1, skill("c1", "count"), skill("f1", "fail"))
        await h.until(lambda: h.server.has(lru1, "f1", S.FAILURE), what="f1 failure")
        assert h.server.has(lru1, "c1", S.SUCCESS, "7")
        assert h.server.applied[lru1][-1].info == "arm fault 3"


async def test_a_broken_link_model_is_said_once(
    harness: Harness, caplog: pytest.LogCaptureFixture
) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)
        polled = asyncio.Event()

        class Radio:  # an integrator's link model without in_range()
            quality = 0.7

            def __getattr__(self, name: str) -> object:
                polled.set()
                raise AttributeError(name)

        a.link = Radio()  # type: ignore[assignment]
        await a.start()
        await h.registered(lru1)  # assumed in range: it registers
        await asyncio.wait_for(polled.wait(), 10)
        await a.wait_acknowledged(10)
        said = [r for r in caplog.records if "agent.link.in_range() failed" in r.getMessage()]
        assert len(said) == 1


async def test_the_context_coroutines_refuse_a_plain_function_handler(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)

        @a.skill("drill")
        def drill(ctx):
            ctx.sleep(0.5)  # forgot it is a coroutine: would neither wait nor honour a pause

        await h.start(a)
        await h.run(lru1, skill("d1", "drill"))
        await h.until(lambda: h.server.has(lru1, "d1", S.FAILURE), what="d1 failure")
        assert h.server.applied[lru1][-1].info == (
            "RuntimeError: ctx.sleep() is for coroutine handlers (async def); the handler of "
            "drill is a plain function running in a thread: use ctx.check() between blocking "
            "steps, or make it a coroutine"
        )


async def test_a_plain_handler_that_ignores_a_stop_is_waited_for_before_the_skill_runs_again(
    harness: Harness,
) -> None:
    """Its thread cannot be cancelled: the next run must not start a second
    handler driving the same robot while the first one still does."""
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)
        release = threading.Event()
        started = [threading.Event(), threading.Event()]
        lock = threading.Lock()
        running = [0, 0]  # now, most at once

        @a.skill("work")
        def work(ctx):  # never calls ctx.check()
            with lock:
                running[0] += 1
                running[1] = max(running[1], running[0])
                n = sum(e.is_set() for e in started)
            started[n].set()
            if n == 0:
                release.wait(30)
            with lock:
                running[0] -= 1

        await h.start(a)
        await h.run(lru1, skill("s1"))
        await asyncio.to_thread(started[0].wait, 30)
        assert (await h.server.command(lru1, Stop())).ok
        await h.server.command(lru1, Run())
        await h.until(
            lambda: sum(r.id == "s1" and r.status == S.RUNNING for r in h.local[lru1]) == 2,
            what="s1 running again",
        )
        assert a.telemetry().info == "waiting for the stopped skill's handler to return"
        assert not started[1].is_set()
        release.set()
        await h.until(lambda: h.made(lru1, "s1", S.SUCCESS), what="s1 done")
        assert started[1].is_set() and running[1] == 1
