"""backend.agent (the robot agent SDK) against a real Zenoh router and a fake server.

Every wait is on an event with a timeout (`harness.until`, `wait_for`); the
few "must NOT happen" checks wait a bounded time for an event that must not
come (`never`).
"""

from __future__ import annotations

import asyncio
import sys
import threading
import time
from datetime import UTC, datetime
from pathlib import Path

import pytest

from backend.agent import Failure, RobotAgent, SkillFailed, SkillStopped, Success
from backend.core.library import SkillSignature
from backend.core.model import Policies, Pose, Position, SkillInstance, Status
from backend.protocol.keys import Keys
from backend.protocol.messages import (
    BarrierInfo,
    Dequeue,
    ErrorReply,
    Pause,
    Reset,
    Run,
    Stop,
    Telemetry,
)
from backend.transport import QueryError, subscribe_to_queue

from .conftest import WAIT, Harness, skill

ROOT = Path(__file__).resolve().parents[2]

S = Status


async def never(event: asyncio.Event, within: float = 0.3) -> None:
    """Assert that `event` is not set within `within` seconds."""
    with pytest.raises(TimeoutError):
        await asyncio.wait_for(event.wait(), within)


class _Lazy(dict):
    """dict that creates an asyncio.Event for a missing key."""

    def __missing__(self, key: str) -> asyncio.Event:
        self[key] = asyncio.Event()
        return self[key]


def gated_handler(agent: RobotAgent, name: str = "work") -> tuple[_Lazy, _Lazy]:
    """Register an async handler `name` that sets started[id], then waits for
    gates[id] (set by the test) and passes a checkpoint."""
    started: _Lazy = _Lazy()
    gates: _Lazy = _Lazy()

    @agent.skill(name, version="1.0.0")
    async def handler(ctx, **params):
        started[ctx.skill.id].set()
        await gates[ctx.skill.id].wait()
        await ctx.checkpoint()

    return started, gates


# ---------------------------------------------------------------- registration


async def test_registers_with_manifest_and_again_after_server_restart(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        h.server.last_seq[lru1] = 41  # reports of a previous run of this robot
        a = h.agent(
            lru1, "rover", modules={"nav": "2.1.0", "arm": "0.3.1"}, properties={"camera": True}
        )

        @a.skill("drive_to", version="1.2.0")
        async def drive_to(ctx, goal):
            return None

        @a.skill("scan", version="0.9.1")
        def scan(ctx):
            return True

        await a.start()
        await h.registered(lru1)
        m = h.server.registrations_of(lru1)[0].manifest
        assert (m.name, m.type) == (lru1, "rover")
        assert {(x.name, x.version) for x in m.modules} == {("nav", "2.1.0"), ("arm", "0.3.1")}
        assert m.properties == {"camera": True}
        assert m.skills == {"drive_to": "1.2.0", "scan": "0.9.1"}
        assert h.server.registrations_of(lru1)[0].queue == []

        # numbering continues after the server's last applied report
        await h.server.enqueue(lru1, skill("d1", "drive_to", goal={"x": 1.0}))
        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "d1", S.SUCCESS), what="d1 success")
        # the answers to the enqueue and the run are 42 and 43
        assert h.server.seqs(lru1) == [44, 45] and h.server.downlink(lru1) == [42, 43, 44, 45]

        # the server restarts (its token goes and comes back): the agent
        # registers again, with its queue (halted first, else d2 would start:
        # a robot in run mode runs what is synchronized next)
        await h.server.command(lru1, Pause())
        await h.server.enqueue(lru1, skill("d2", "drive_to", goal={"x": 2.0}))
        h.server.vanish()
        h.server.appear()
        await h.registered(lru1, count=2)
        last = h.server.registrations_of(lru1)[-1]
        assert [(q.id, q.status) for q in last.queue] == [("d2", S.IDLE_SYNCHRONIZED)]


# ---------------------------------------------------------------- execution


async def test_enqueue_run_success_with_params_typed_by_kind_and_consecutive_seqs(
    harness: Harness,
) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)
        got: dict[str, dict] = {}

        @a.skill("drive_to", version="1.0.0")
        async def drive_to(ctx, **params):
            got[ctx.skill.id] = params
            ctx.progress(0.5, "half way", eta_s=1.0)
            await ctx.sleep(0.01)
            assert ctx.pose("goal").x == 1.0
            assert ctx.position("goal") == Position(x=1.0, y=2.0, z=0.0)

        await a.start()
        await h.registered(lru1)
        goal = {"x": 1.0, "y": 2.0, "z": 0.0, "roll": 0.0, "pitch": 0.0, "yaw": 0.5}
        area = [
            {"x": 0.0, "y": 0.0, "z": 0.0},
            {"x": 1.0, "y": 0.0, "z": 0.0},
            {"x": 0.0, "y": 1.0, "z": 0.0},
        ]
        kinds = {"goal": "pose", "region": "area", "poi": "marker", "n": "int", "speed": "float"}
        reply = await h.server.enqueue(
            lru1,
            skill("s1", "drive_to", goal=goal, region=area, poi="stone1", n=3, speed=0.5),
            skill("s2", "drive_to", goal=goal),
            kinds={"drive_to": {**kinds, "shape": "dict"}},
        )
        assert reply.ok and reply.ids == ["s1", "s2"]
        # halted until `run`
        assert a.queue == ["s1", "s2"] and a.active is None and reply.reports == []

        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "s2", S.SUCCESS), what="s2 success")
        assert h.server.trail(lru1) == [
            ("s1", "running"),
            ("s1", "success"),
            ("s2", "running"),
            ("s2", "success"),
        ]
        # reports and answers share one sequence: answers 1, 2, then the reports
        assert h.server.seqs(lru1) == [3, 4, 5, 6] and not h.server.gaps
        assert h.server.downlink(lru1) == list(range(1, 7))
        params = got["s1"]
        assert params["goal"] == Pose(x=1.0, y=2.0, yaw=0.5)
        assert params["region"] == [Position(x=0.0), Position(x=1.0), Position(y=1.0)]
        assert (params["poi"], params["n"], params["speed"]) == ("stone1", 3, 0.5)
        # every parameter arrives: one left unset is None
        assert got["s2"]["region"] is None and got["s2"]["shape"] is None
        # every report was acknowledged
        await a.wait_acknowledged(WAIT)
        assert a.pending_reports == []


async def test_enqueue_is_idempotent_refuses_unknown_skills_and_front_goes_first(
    harness: Harness,
) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)
        gated_handler(a)
        await a.start()
        await h.registered(lru1)
        reply = await h.server.enqueue(lru1, skill("s1"), skill("s2"))
        assert reply.ids == ["s1", "s2"]
        reply = await h.server.enqueue(lru1, skill("s2"), skill("s3"))  # s2 re-sent
        assert reply.ids == ["s2", "s3"] and a.queue == ["s1", "s2", "s3"]
        reply = await h.server.enqueue(lru1, skill("r1"), front=True)  # a retry
        assert a.queue == ["r1", "s1", "s2", "s3"]
        reply = await h.server.enqueue(lru1, skill("x1", "fly"))
        assert not reply.ok and "no handler for skill fly" in reply.reason
        assert a.queue == ["r1", "s1", "s2", "s3"]


async def test_telemetry_is_published(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1, telemetry_hz=20.0)
        a.pose = lambda: Pose(x=1.5, y=-2.0, yaw=0.25)
        a.battery = lambda: 0.8
        a.link.quality = 0.6
        started, _gates = gated_handler(a)
        _sub, samples = subscribe_to_queue(h.server.session, Keys.telemetry(lru1))
        await a.start()
        await h.registered(lru1)
        await h.server.enqueue(lru1, skill("s1"))
        await h.server.command(lru1, Run())
        await asyncio.wait_for(started["s1"].wait(), WAIT)
        async with asyncio.timeout(WAIT):
            while True:
                t = Telemetry.model_validate_json((await samples.get()).payload)
                if t.skill == "s1" and t.mode == "running":
                    break
        assert (t.robot, t.pose, t.battery, t.link, t.in_range) == (
            lru1,
            Pose(x=1.5, y=-2.0, yaw=0.25),
            0.8,
            0.6,
            True,
        )


async def test_telemetry_arrives_one_link_delay_late(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1, telemetry_hz=20.0)
        a.link.delay_s = 0.4
        _sub, samples = subscribe_to_queue(h.server.session, Keys.telemetry(lru1))
        await a.start()
        async with asyncio.timeout(WAIT):
            raw = await samples.get()
        received = datetime.now(UTC)
        t = Telemetry.model_validate_json(raw.payload)
        # stamped when measured, delivered after the one-way delay
        assert (received - t.at).total_seconds() >= 0.35


async def test_pause_and_resume(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)
        started, gates = gated_handler(a)
        passed = asyncio.Event()

        @a.skill("nap", version="1.0.0")
        async def nap(ctx):
            started[ctx.skill.id].set()
            await gates[ctx.skill.id].wait()
            await ctx.sleep(0.05)  # checkpoint-aware: blocks while paused
            passed.set()

        await a.start()
        await h.registered(lru1)
        await h.server.enqueue(lru1, skill("s1", "nap"))
        await h.server.command(lru1, Run())
        await asyncio.wait_for(started["s1"].wait(), WAIT)

        reply = await h.server.command(lru1, Pause())
        assert reply.ok
        assert [(r.id, r.status) for r in reply.reports][-1] == ("s1", S.PAUSED)
        assert a.telemetry().mode == "paused"
        gates["s1"].set()
        await never(passed)  # held at the checkpoint while paused

        await h.server.command(lru1, Run())  # run on a paused robot resumes
        await h.until(lambda: h.server.has(lru1, "s1", S.SUCCESS), what="success")
        assert passed.is_set()
        assert h.server.trail(lru1) == [
            ("s1", "running"),
            ("s1", "paused"),
            ("s1", "running"),
            ("s1", "success"),
        ]


async def test_stop_returns_to_queue_and_run_restarts_from_the_beginning(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)
        calls: list[int] = []
        cancelled = asyncio.Event()
        first = asyncio.Event()

        @a.skill("work", version="1.0.0")
        async def work(ctx):
            calls.append(len(calls) + 1)
            if len(calls) == 1:
                first.set()
                try:
                    await asyncio.Event().wait()  # forever, until stopped
                except asyncio.CancelledError:
                    cancelled.set()
                    raise

        await a.start()
        await h.registered(lru1)
        await h.server.enqueue(lru1, skill("s1"), skill("s2"))
        await h.server.command(lru1, Run())
        await asyncio.wait_for(first.wait(), WAIT)

        reply = await h.server.command(lru1, Stop())
        assert reply.ok
        assert (reply.reports[-1].id, reply.reports[-1].status) == ("s1", S.IDLE_SYNCHRONIZED)
        await asyncio.wait_for(cancelled.wait(), WAIT)  # the handler was cancelled
        assert a.active is None and a.queue == ["s1", "s2"]  # back at the head

        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "s2", S.SUCCESS), what="s2 success")
        assert calls == [1, 2, 3]  # s1 from the beginning, then s2
        assert h.server.trail(lru1) == [
            ("s1", "running"),
            ("s1", "idle_synchronized"),
            ("s1", "running"),
            ("s1", "success"),
            ("s2", "running"),
            ("s2", "success"),
        ]
        assert h.server.downlink(lru1) == list(range(1, len(h.server.downlink(lru1)) + 1))
        assert len(h.server.seqs(lru1)) == 6


async def test_failure_halts_then_run_continues_and_exceptions_are_failures(
    harness: Harness,
) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)

        @a.skill("stuck", version="1.0.0")
        async def stuck(ctx):
            raise SkillFailed("wheel stuck in sand")

        @a.skill("buggy", version="1.0.0")
        def buggy(ctx):
            return 1 / 0

        @a.skill("soft", version="1.0.0")
        async def soft(ctx):
            return Failure("no stone here")

        @a.skill("ok", version="1.0.0")
        async def ok(ctx):
            return True

        @a.skill("found", version="1.0.0")
        def found(ctx):
            return Success("stone s7, score 0.9")

        await a.start()
        await h.registered(lru1)
        await h.server.enqueue(
            lru1,
            skill("f1", "stuck"),
            skill("f2", "buggy"),
            skill("f3", "soft"),
            skill("k1", "ok"),
            skill("k2", "found"),
        )
        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "f1", S.FAILURE), what="f1 failure")
        assert h.server.applied[lru1][-1].info == "wheel stuck in sand"
        assert a.active is None and a.queue == ["f2", "f3", "k1", "k2"]  # halted

        await h.server.command(lru1, Run())  # continue with the next
        await h.until(lambda: h.server.has(lru1, "f2", S.FAILURE), what="f2 failure")
        assert h.server.applied[lru1][-1].info == "ZeroDivisionError: division by zero"
        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "f3", S.FAILURE, "no stone here"), what="f3")
        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "k1", S.SUCCESS), what="k1 success")
        k1 = [r for r in h.server.applied[lru1] if r.id == "k1" and r.status == S.SUCCESS]
        assert [r.info for r in k1] == [""]  # plain success: no result text
        # the queue went on (run mode stays after a success); Success carries a result text
        await h.until(
            lambda: h.server.has(lru1, "k2", S.SUCCESS, "stone s7, score 0.9"),
            what="k2 success with text",
        )
        assert not h.server.gaps


async def test_autonomous_retries_report_running_with_next_attempt(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)
        attempts: list[int] = []

        @a.skill("grasp", version="1.0.0")
        async def grasp(ctx):
            attempts.append(ctx.attempt)
            if len(attempts) == 1:
                raise SkillFailed("slipped")

        await a.start()
        await h.registered(lru1)
        s = SkillInstance(id="g1", skill="grasp", policies=Policies(retries=2))
        await h.server.enqueue(lru1, s)
        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "g1", S.SUCCESS), what="success")
        got = [(r.status, r.attempt, r.info) for r in h.server.applied[lru1]]
        assert got == [
            (S.RUNNING, 1, ""),
            (S.RUNNING, 2, "retry 1/2 after: slipped"),
            (S.SUCCESS, 2, ""),
        ]
        assert attempts == [1, 2]


async def test_sync_handler_progress_pause_and_stop(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)
        progressed = threading.Event()
        blocked = threading.Event()
        ended: list[str] = []
        ended_evt = threading.Event()

        @a.skill("drill", version="1.0.0")
        def drill(ctx, depth):
            try:
                i = 0
                while True:
                    i += 1
                    ctx.progress(min(1.0, i / 1000), f"depth {depth}")
                    progressed.set()
                    if ctx.paused:
                        blocked.set()
                    ctx.check()  # blocks while paused, raises SkillStopped on stop
                    time.sleep(0.005)  # the drill's work
            except SkillStopped:
                ended.append("stopped")
                ended_evt.set()
                raise

        await a.start()
        await h.registered(lru1)
        await h.server.enqueue(lru1, skill("d1", "drill", depth=0.3))
        await h.server.command(lru1, Run())
        assert await asyncio.to_thread(progressed.wait, WAIT)

        await h.server.command(lru1, Pause())
        assert await asyncio.to_thread(blocked.wait, WAIT)
        telemetry = a.telemetry()
        assert telemetry.mode == "paused" and telemetry.skill == "d1"
        assert telemetry.progress is not None and telemetry.progress > 0

        reply = await h.server.command(lru1, Stop())
        assert reply.reports[-1].status == S.IDLE_SYNCHRONIZED
        assert await asyncio.to_thread(ended_evt.wait, WAIT)
        assert ended == ["stopped"] and a.queue == ["d1"]


async def test_dequeue_removes_unstarted_and_keeps_started(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)
        started, gates = gated_handler(a)
        await a.start()
        await h.registered(lru1)
        await h.server.enqueue(lru1, skill("s1"), skill("s2"), skill("s3"), skill("s4"))
        await h.server.command(lru1, Run())
        await asyncio.wait_for(started["s1"].wait(), WAIT)

        # the operator unsynchronizes from s1, which started meanwhile (the race)
        reply = await h.server.command(lru1, Dequeue(ids=["s1", "s3", "s4"]))
        assert reply.ids == ["s3", "s4"] and reply.kept == ["s1"]
        # the reply carries s1's running report, so the server knows why it was kept
        assert h.server.has(lru1, "s1", S.RUNNING)
        assert a.queue == ["s2"]

        # a finished skill is kept too (its success comes with the reply)
        gates["s1"].set()
        await h.until(lambda: h.made(lru1, "s2", S.RUNNING), what="s2 running")
        reply = await h.server.command(lru1, Dequeue(ids=["s1"]))
        assert reply.ids == [] and reply.kept == ["s1"]
        assert h.server.has(lru1, "s1", S.SUCCESS)


async def test_reset_stops_and_removes_everything(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)
        started, _gates = gated_handler(a)
        await a.start()
        await h.registered(lru1)
        await h.server.enqueue(lru1, skill("s1"), skill("s2"), skill("s3"))
        await h.server.command(lru1, Run())
        await asyncio.wait_for(started["s1"].wait(), WAIT)

        reply = await h.server.command(lru1, Reset())
        assert reply.ok and reply.ids == ["s1", "s2", "s3"]
        assert (reply.reports[-1].id, reply.reports[-1].status) == ("s1", S.IDLE_SYNCHRONIZED)
        assert a.queue == [] and a.active is None
        assert a.telemetry().mode == "idle"


async def test_out_of_range_refuses_commands_and_queues_reports(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)
        started, gates = gated_handler(a)
        await a.start()
        await h.registered(lru1)
        await h.server.enqueue(lru1, skill("s1"), skill("s2"))
        await h.server.command(lru1, Run())
        await h.until(lambda: h.server.has(lru1, "s1", S.RUNNING), what="s1 running")
        await a.wait_acknowledged(WAIT)  # the ack may still be on its way

        a.link.reachable = False
        with pytest.raises(QueryError) as refused:
            await h.server.command(lru1, Pause())
        error = ErrorReply.model_validate_json(refused.value.payload)
        assert error.code == "unreachable"
        assert error.message == f"{lru1} is out of communication range"
        assert a.telemetry().in_range is False

        # the robot keeps working autonomously; its reports wait in the outbox
        gates["s1"].set()
        await h.until(lambda: h.made(lru1, "s2", S.RUNNING), what="s2 running")
        gates["s2"].set()
        await h.until(lambda: h.made(lru1, "s2", S.SUCCESS), what="s2 success")
        assert not h.server.has(lru1, "s1", S.SUCCESS)
        assert [(r.id, r.status) for r in a.pending_reports] == [
            ("s1", S.SUCCESS),
            ("s2", S.RUNNING),
            ("s2", S.SUCCESS),
        ]

        a.link.reachable = True  # back in range: flushed, nothing lost, in order
        await h.until(lambda: h.server.has(lru1, "s2", S.SUCCESS), what="flush")
        assert h.server.trail(lru1) == [
            ("s1", "running"),
            ("s1", "success"),
            ("s2", "running"),
            ("s2", "success"),
        ]
        # reports and answers share one sequence: answers 1, 2, then the reports
        assert h.server.seqs(lru1) == [3, 4, 5, 6] and not h.server.gaps
        assert h.server.downlink(lru1) == list(range(1, 7))
        reply = await h.server.command(lru1, Pause())  # reachable again
        assert reply.ok


async def test_pause_out_of_comms_policy_and_recharge_policy(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1)
        level = [0.1]
        a.battery = lambda: level[0]
        started, gates = gated_handler(a)
        recharges: list[tuple[str, float]] = []
        # the library's recharge, as the server sends it with the registration
        h.server.signatures["recharge"] = SkillSignature(
            params={"target_level": "float"}, defaults={"target_level": 0.95}
        )

        @a.skill("recharge", version="1.0.0")
        async def recharge(ctx, target_level: float):
            recharges.append((ctx.skill.id, target_level))
            level[0] = 1.0

        await a.start()
        await h.registered(lru1)
        s1 = SkillInstance(
            id="s1", skill="work", policies=Policies(recharge_below=0.3, pause_out_of_comms=True)
        )
        await h.server.enqueue(lru1, s1)
        await h.server.command(lru1, Run())
        await asyncio.wait_for(started["s1"].wait(), WAIT)
        assert recharges == [("s1", 0.95)]  # with the library's default, as the server sent it
        assert h.made(lru1, "s1", S.RUNNING, "recharging first: battery 10% below 30%")

        a.link.reachable = False
        await h.until(
            lambda: h.made(lru1, "s1", S.PAUSED, "out of communication range"), what="auto pause"
        )
        gates["s1"].set()  # it would finish, but it is held at its checkpoint
        a.link.reachable = True
        await h.until(lambda: h.server.has(lru1, "s1", S.SUCCESS), what="success")
        assert h.server.trail(lru1) == [
            ("s1", "running"),
            ("s1", "running"),
            ("s1", "paused"),
            ("s1", "running"),
            ("s1", "success"),
        ]


# ---------------------------------------------------------------- barriers


def barrier_skill(
    sid: str, partner: str, partner_skill: str
) -> tuple[SkillInstance, dict[str, BarrierInfo]]:
    return skill(sid, "meet"), {sid: BarrierInfo(barrier="b1", partners={partner: partner_skill})}


def meet_handler(
    agent: RobotAgent, started: dict[str, float], events: dict[str, asyncio.Event]
) -> None:
    @agent.skill("meet", version="1.0.0")
    async def meet(ctx):
        started[agent.name] = time.monotonic()
        events[agent.name].set()


async def test_barrier_neither_starts_before_both_are_ready(harness: Harness) -> None:
    async with harness as h:
        lru1, lru2 = h.names("lru1", "lru2")
        a, b = h.agent(lru1), h.agent(lru2)
        started: dict[str, float] = {}
        events = {lru1: asyncio.Event(), lru2: asyncio.Event()}
        waiting_at: dict[str, float] = {}
        for agent in (a, b):
            meet_handler(agent, started, events)
            agent.report_listeners.append(
                lambda r: (
                    waiting_at.setdefault(r.robot, time.monotonic())
                    if r.status == S.SYNCHWAITING
                    else None
                )
            )
        await a.start()
        await b.start()
        await h.registered(lru1, lru2)

        m1, bar1 = barrier_skill("m1", lru2, "m2")
        await h.server.enqueue(lru1, m1, barriers=bar1)
        await h.server.command(lru1, Run())
        await h.until(
            lambda: h.made(lru1, "m1", S.SYNCHWAITING, f"waiting for {lru2}"), what="lru1 waits"
        )
        await never(events[lru1])  # lru1 does not start alone

        m2, bar2 = barrier_skill("m2", lru1, "m1")
        await h.server.enqueue(lru2, m2, barriers=bar2)
        await h.server.command(lru2, Run())
        await asyncio.wait_for(asyncio.gather(events[lru1].wait(), events[lru2].wait()), WAIT)
        # both started only after both were waiting at the barrier
        assert min(started.values()) >= max(waiting_at.values())
        await h.until(
            lambda: h.server.has(lru1, "m1", S.SUCCESS) and h.server.has(lru2, "m2", S.SUCCESS),
            what="both succeed",
        )
        for robot, sid in ((lru1, "m1"), (lru2, "m2")):
            assert h.server.trail(robot) == [
                (sid, "synchwaiting"),
                (sid, "running"),
                (sid, "success"),
            ]


async def test_barrier_partner_offline_and_stop_withdraws_readiness(harness: Harness) -> None:
    async with harness as h:
        lru1, lru2 = h.names("lru1", "lru2")
        a, b = h.agent(lru1), h.agent(lru2)
        started: dict[str, float] = {}
        events = {lru1: asyncio.Event(), lru2: asyncio.Event()}
        meet_handler(a, started, events)
        meet_handler(b, started, events)
        await a.start()
        await b.start()
        await h.registered(lru1, lru2)

        m1, bar1 = barrier_skill("m1", lru2, "m2")
        await h.server.enqueue(lru1, m1, barriers=bar1)
        await h.server.command(lru1, Run())
        await h.until(
            lambda: h.server.has(lru1, "m1", S.SYNCHWAITING, f"waiting for {lru2}"), what="waits"
        )

        await b.stop()  # the partner goes offline (session closed)
        await h.until(
            lambda: h.server.has(lru1, "m1", S.SYNCHWAITING, f"waiting for {lru2} (offline)"),
            what="partner reported offline",
        )
        assert f"{lru2} (offline)" in a.telemetry().info

        # stop while waiting: back to the queue, readiness withdrawn
        reply = await h.server.command(lru1, Stop())
        assert reply.reports[-1].status == S.IDLE_SYNCHRONIZED and a.queue == ["m1"]

        # the partner comes back and reaches the barrier: lru1 is not ready any more
        b2 = h.agent(lru2)
        meet_handler(b2, started, events)
        await b2.start()
        await h.registered(lru2, count=2)
        m2, bar2 = barrier_skill("m2", lru1, "m1")
        await h.server.enqueue(lru2, m2, barriers=bar2)
        await h.server.command(lru2, Run())
        await h.until(
            lambda: h.made(lru2, "m2", S.SYNCHWAITING, f"waiting for {lru1}"), what="lru2 waits"
        )
        await never(events[lru2])

        await h.server.command(lru1, Run())  # lru1 comes to the barrier again: both start
        await asyncio.wait_for(asyncio.gather(events[lru1].wait(), events[lru2].wait()), WAIT)
        await h.until(
            lambda: h.server.has(lru1, "m1", S.SUCCESS) and h.server.has(lru2, "m2", S.SUCCESS),
            what="both succeed",
        )
        assert not h.server.gaps


# ---------------------------------------------------------------- world


async def test_ask_and_tell_between_agents_are_counted(harness: Harness) -> None:
    async with harness as h:
        lru1, lru2 = h.names("lru1", "lru2")
        a, b = h.agent(lru1), h.agent(lru2)
        told: list[tuple[dict, str]] = []
        got_tell = asyncio.Event()

        a.on_ask(
            "stone",
            lambda data, sender: {"x": 3.0, "y": 4.0, "region": data["region"], "for": sender},
        )

        async def on_box(data, sender):
            told.append((data, sender))
            got_tell.set()

        a.on_tell("box", on_box)
        answers: dict[str, object] = {}

        @b.skill("fetch", version="1.0.0")
        async def fetch(ctx):
            answers["stone"] = await ctx.ask(lru1, "stone", {"region": "r1"})
            answers["unknown"] = await ctx.ask(lru1, "weather")
            answers["told"] = await ctx.tell(lru1, "box", {"at": [1, 2]})
            answers["nobody"] = await ctx.ask(h.name("lru9"), "stone")

        await a.start()
        await b.start()
        await h.registered(lru1, lru2)
        await h.server.enqueue(lru2, skill("f1", "fetch"))
        await h.server.command(lru2, Run())
        await h.until(lambda: h.server.has(lru2, "f1", S.SUCCESS), what="fetch done")
        await asyncio.wait_for(got_tell.wait(), WAIT)

        assert answers == {
            "stone": {"x": 3.0, "y": 4.0, "region": "r1", "for": lru2},
            "unknown": None,
            "told": True,
            "nobody": None,
        }
        assert told == [({"at": [1, 2]}, lru2)]
        assert b.world_stats == {
            "asks_sent": 3,
            "tells_sent": 1,
            "asks_failed": 1,
            "tells_failed": 0,
            "asks_received": 0,
            "tells_received": 0,
        }
        assert a.world_stats == {
            "asks_sent": 0,
            "tells_sent": 0,
            "asks_failed": 0,
            "tells_failed": 0,
            "asks_received": 2,
            "tells_received": 1,
        }


async def test_a_robot_out_of_reach_is_not_asked(harness: Harness) -> None:
    async with harness as h:
        lru1, lru2 = h.names("lru1", "lru2")
        a, b = h.agent(lru1), h.agent(lru2)
        a.on_ask("stone", lambda data, sender: {"x": 1.0})
        a.on_tell("box", lambda data, sender: None)
        b.link.can_reach = lambda robot: robot != lru1  # e.g. a ridge between them
        answers: dict[str, object] = {}

        @b.skill("fetch", version="1.0.0")
        async def fetch(ctx):
            answers["stone"] = await ctx.ask(lru1, "stone")
            answers["told"] = await ctx.tell(lru1, "box", {})

        await a.start()
        await b.start()
        await h.registered(lru1, lru2)
        await h.server.enqueue(lru2, skill("f1", "fetch"))
        await h.server.command(lru2, Run())
        await h.until(lambda: h.server.has(lru2, "f1", S.SUCCESS), what="fetch done")
        assert answers == {"stone": None, "told": False}
        assert (b.world_stats["asks_failed"], b.world_stats["tells_failed"]) == (1, 1)
        assert (a.world_stats["asks_received"], a.world_stats["tells_received"]) == (
            0,
            0,
        )  # never sent


# ---------------------------------------------------------------- shutdown


AGENT_SCRIPT = """
import asyncio, sys, time
sys.path.insert(0, {root!r})
from backend.agent import RobotAgent

async def main():
    agent = RobotAgent(sys.argv[2], "rover", connect=[sys.argv[1]])

    @agent.skill("spin", version="1.0.0")
    def spin(ctx):  # a sync handler that never checks for stop
        while True:
            time.sleep(0.05)

    async with agent:
        print("ready", flush=True)
        await asyncio.to_thread(sys.stdin.readline)
    print("stopped", flush=True)

asyncio.run(main())
"""


async def test_agent_process_exits_promptly_after_stop(harness: Harness) -> None:
    async with harness as h:
        lru9 = h.name("lru9")
        proc = await asyncio.create_subprocess_exec(
            sys.executable,
            "-c",
            AGENT_SCRIPT.format(root=str(ROOT)),
            h.endpoint,
            lru9,
            stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE,
        )
        try:
            assert proc.stdin is not None and proc.stdout is not None
            assert (await asyncio.wait_for(proc.stdout.readline(), WAIT)).strip() == b"ready"
            await h.until(lambda: bool(h.server.registrations_of(lru9)), what=lru9)
            await h.server.enqueue(lru9, skill("x1", "spin"))
            await h.server.command(lru9, Run())
            await h.until(lambda: h.server.has(lru9, "x1", S.RUNNING), what="x1 running")

            proc.stdin.write(b"stop\n")
            await proc.stdin.drain()
            assert (await asyncio.wait_for(proc.stdout.readline(), WAIT)).strip() == b"stopped"
            assert await asyncio.wait_for(proc.wait(), 5.0) == 0
        finally:
            if proc.returncode is None:
                proc.kill()
                await proc.wait()
