"""A mission loaded while robots are connected never resurrects statuses the
robots do not hold (issue 28): the saved file of a running mission, loaded
into the same server or into a fresh server and fleet, comes in as a plan;
the robots register again and are reconciled; new work runs and no report
is refused."""

from __future__ import annotations

import asyncio

import pytest

from backend.agent import RobotAgent
from backend.client.client import AlertRaised, OperationRefused
from backend.core.model import Status
from backend.core.ops import Control, LoadMission, Sync
from backend.files.missions import load_mission, save_mission_file

from .harness import serving

WAIT = 15.0
SKILLS = ["drive_to", "explore", "take_science_image", "identify_stone", "recharge"]


class Robot:
    """lru1 on the SDK: every skill succeeds at once, but take_science_image
    holds until `release` is set (so a mission can be saved while it runs)."""

    def __init__(self, endpoints: list[str]) -> None:
        self.release = asyncio.Event()
        self.agent = RobotAgent("lru1", "lru_science", connect=endpoints, request_timeout=10)
        for skill in SKILLS:
            self.agent.add_skill(skill, self._handler, version="1.0.0", raw=True)

    async def _handler(self, ctx, **params) -> None:
        if ctx.skill.skill == "take_science_image":
            await self.release.wait()

    async def __aenter__(self) -> Robot:
        await self.agent.start()
        await self.agent.wait_registered(WAIT)
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.agent.stop()


def statuses(m) -> dict[str, Status]:
    return {s.id: s.status for s in m.tasks["lru1"]}


async def run_until_holding(client) -> None:
    """lru1-1 done, lru1-2 running (held)."""
    await client.submit(Sync(robot="lru1"))
    await client.submit(Control(op="run", robot="lru1"))
    await client.wait_for(
        lambda m: statuses(m) == {"lru1-1": Status.SUCCESS, "lru1-2": Status.RUNNING}, WAIT
    )


def refused_reports(alerts: list) -> list[str]:
    return [a.message for a in alerts if a.kind == "report_refused"]


async def new_work_runs(client, robot: Robot, alerts: list) -> None:
    """The reloaded plan runs to its end; no report of it is refused."""
    robot.release.set()
    await client.submit(Sync(robot="lru1"))
    await client.submit(Control(op="run", robot="lru1"))
    m = await client.wait_for(lambda m: statuses(m)["lru1-2"] == Status.SUCCESS, WAIT)
    assert statuses(m) == {"lru1-1": Status.SUCCESS, "lru1-2": Status.SUCCESS}
    assert refused_reports(alerts) == []
    assert m.report_seqs["lru1"] == robot.agent._queue.seq  # every message applied


async def test_the_saved_file_of_a_running_mission_loads_into_a_fresh_server_as_a_plan(tmp_path):
    """Main: lru1 came back holding a `running` skill it never got, and a
    sync after that never ran."""
    saved = tmp_path / "elsewhere" / "running.yaml"
    saved.parent.mkdir()
    async with serving(tmp_path / "a.db") as (_, client):
        async with Robot(client.endpoints):
            await run_until_holding(client)
            kept = save_mission_file(client.mission, client.library, saved)
            assert kept.library_file == saved.with_name("running.library.yaml")
    mission, _ = load_mission(saved)  # loads from where it was written
    assert statuses(mission)["lru1-2"] == Status.RUNNING  # the file keeps the state
    async with serving(tmp_path / "b.db") as (server, client):
        alerts: list = []
        client.add_listener(lambda e: alerts.append(e.alert) if isinstance(e, AlertRaised) else 0)
        async with Robot(client.endpoints) as robot:
            with pytest.raises(OperationRefused) as keep:
                await client.submit(LoadMission(mission=mission, keep_state=True))
            assert keep.value.reply.code == "robots_online" and "lru1" in keep.value.reply.message
            reply = await client.submit(LoadMission(mission=mission))
            assert reply.value == {"reset": ["lru1-2"], "dissolved": []}
            m = await client.wait_for(lambda m: m.revision >= reply.revision, WAIT)
            assert statuses(m) == {"lru1-1": Status.SUCCESS, "lru1-2": Status.IDLE}
            await new_work_runs(client, robot, alerts)
            assert server.robot_link._renew == set()  # lru1 registered again


async def test_the_saved_file_loaded_into_the_running_server_leaves_no_report_refused(tmp_path):
    saved = tmp_path / "running.yaml"
    async with serving(tmp_path / "a.db") as (_, client):
        alerts: list = []
        client.add_listener(lambda e: alerts.append(e.alert) if isinstance(e, AlertRaised) else 0)
        async with Robot(client.endpoints) as robot:
            await run_until_holding(client)
            save_mission_file(client.mission, client.library, saved)
            done = await client.submit(Control(op="reset", robot="lru1"))
            await client.wait_command(done.value["commands"]["lru1"], WAIT)
            mission, _ = load_mission(saved)
            registered = robot.agent._registrar.last_reply
            reply = await client.submit(LoadMission(mission=mission))
            assert reply.value["reset"] == ["lru1-2"]
            await new_work_runs(client, robot, alerts)
            assert robot.agent._registrar.last_reply is not registered  # reconciled again
