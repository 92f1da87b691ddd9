"""Telemetry on change with deadbands, a rate cap and a heartbeat, in compact JSON."""

from __future__ import annotations

import asyncio
import math
from datetime import UTC, datetime

from backend.agent import TelemetryPolicy
from backend.agent.telemetry import changed, encode
from backend.core.model import Pose
from backend.protocol.keys import Keys
from backend.protocol.messages import Telemetry
from backend.transport import subscribe_to_queue

from .conftest import WAIT, Harness

P = TelemetryPolicy()


def sample(**kw) -> Telemetry:
    return Telemetry(robot="lru1", at=datetime.now(UTC), **kw)


def test_small_moves_are_not_news_and_the_rest_is():
    old = sample(pose=Pose(x=10.0, y=5.0, yaw=1.0), battery=0.8, mode="running", skill="s1")
    assert not changed(P, old.model_copy(update={"at": datetime.now(UTC)}), old, 0.5)
    for update in (
        {"pose": Pose(x=10.3, y=5.3, yaw=1.0)},  # 0.42 m
        {"pose": Pose(x=10.0, y=5.0, yaw=1.0 + math.radians(4))},
        {"battery": 0.795},
        {"link": 0.97},
        {"progress": None},
    ):
        assert not changed(P, old.model_copy(update=update), old, 0.5), update
    for update in (
        {"pose": Pose(x=10.5, y=5.0, yaw=1.0)},
        {"pose": Pose(x=10.0, y=5.0, yaw=1.0 + math.radians(6))},
        {"battery": 0.79},
        {"mode": "paused"},
        {"skill": "s2"},
        {"info": "12 of 40 m"},
        {"in_range": False},
        {"progress": 0.1},
    ):
        assert changed(P, old.model_copy(update=update), old, 0.5), update
    assert changed(P, old, None, 0.0)  # the first sample


def test_an_eta_is_news_only_when_it_stops_counting_down_as_said():
    old = sample(skill="s1", progress=0.5, eta_s=100.0)
    # 10 s later the ground shows 90 s: 91 is the same news, 70 is not
    assert not changed(P, old.model_copy(update={"eta_s": 91.0}), old, 10.0)
    assert changed(P, old.model_copy(update={"eta_s": 70.0}), old, 10.0)
    assert not changed(P, old.model_copy(update={"eta_s": 5.0}), old, 96.0)  # near the end


def test_the_compact_form_is_the_same_telemetry():
    t = sample(
        pose=Pose(x=12.345678, y=-3.2, yaw=0.612345), battery=0.876543, progress=0.2, eta_s=12.345
    )
    wire = encode(t)
    assert len(wire) < 0.7 * len(encode(t, compact=False))
    back = Telemetry.model_validate_json(wire)
    assert back.pose == Pose(x=12.346, y=-3.2, yaw=0.612)
    assert (back.battery, back.eta_s, back.mode, back.in_range) == (0.877, 12.3, "idle", True)
    assert back.at == t.at


async def test_a_still_robot_sends_once_then_only_its_heartbeat(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        policy = TelemetryPolicy(heartbeat_s=0.3)  # short, for the test
        a = h.agent(lru1, telemetry_hz=50.0, telemetry=policy)
        x = [0.0]
        a.pose = lambda: Pose(x=x[0])
        _sub, samples = subscribe_to_queue(h.server.session, Keys.telemetry(lru1))
        await h.start(a)
        got = [Telemetry.model_validate_json((await asyncio.wait_for(samples.get(), WAIT)).payload)]
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        for _ in range(3):  # 50 looks a second, still robot: heartbeats only
            got.append(
                Telemetry.model_validate_json((await asyncio.wait_for(samples.get(), WAIT)).payload)
            )
        assert loop.time() - t0 >= 2 * policy.heartbeat_s  # 3 heartbeats, not 150 looks
        x[0] = 2.0  # a move beyond the deadband goes out without waiting for the heartbeat
        while True:
            t = Telemetry.model_validate_json((await asyncio.wait_for(samples.get(), WAIT)).payload)
            if t.pose.x == 2.0:
                break
        assert a._telemetry.sent <= len(got) + 3


async def test_the_rate_caps_a_fast_mover(harness: Harness) -> None:
    async with harness as h:
        lru1 = h.name("lru1")
        a = h.agent(lru1, telemetry_hz=5.0)
        loop = asyncio.get_running_loop()
        a.pose = lambda: Pose(x=loop.time() * 100.0)  # 100 m/s: news at every look
        _sub, samples = subscribe_to_queue(h.server.session, Keys.telemetry(lru1))
        await h.start(a)
        await asyncio.wait_for(samples.get(), WAIT)
        t0 = loop.time()
        for _ in range(5):
            await asyncio.wait_for(samples.get(), WAIT)
        assert loop.time() - t0 >= 4 * (1 / 5.0)  # at most 5 a second
