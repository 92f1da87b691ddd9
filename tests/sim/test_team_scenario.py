"""Substitution in the simulator (issue 30): lru1 stops responding at 12
sim-minutes, lru3 (an lru_science) arrives at 15 and asks to join; the
operator adds it, retires lru1 and gives lru1's remaining plan to lru3 (two
actions), which completes it; the server's journal replays to the same
mission. At sim speed 100 (the delays are sim time: nothing is waited out)."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from backend.core.model import FINISHED, Status
from backend.core.ops import AddRobot, AddSkill, Control, NewMission, Reassign, RetireRobot, Sync
from backend.server.journal import Journal
from sim.team import Arrival, Breakdown, parse_break, parse_join

from .conftest import Stack, connect

SPEED = 100.0
LEGS = 20  # 10 m drives at 0.2 m/s, about 50 sim-s each: lru1 is at the 15th at 12 sim-min


def test_break_and_join_are_parsed_with_sentences() -> None:
    assert parse_break("lru1@12m") == Breakdown("lru1", 720.0, "silent")
    assert parse_break("lru2@90s:arm") == Breakdown("lru2", 90.0, "arm")
    assert parse_join("lru3:lru_science@15m") == Arrival("lru3", "lru_science", 900.0)
    for parse, bad, said in (
        (parse_break, "lru1", "expected ROBOT@TIME"),
        (parse_break, "lru1@12m:wheel", "'wheel' is no way to break"),
        (parse_join, "lru3@15m", "expected ROBOT:TYPE@TIME"),
        (parse_join, "3x:lru_science@1m", "must start with a letter"),
        (parse_join, "lru3:lru_science@soon", "not a duration"),
    ):
        with pytest.raises(argparse.ArgumentTypeError, match=said):
            parse(bad)


def _done(m, robot: str) -> bool:
    task = m.tasks.get(robot, [])
    return bool(task) and all(s.status in FINISHED for s in task)


async def test_lru1_breaks_lru3_joins_and_takes_over_its_plan(stack: Stack, tmp_path: Path):
    extra = ["--break", "lru1@12m", "--join", "lru3:lru_science@15m"]
    client, watch = await connect(stack, speed=SPEED, seed=1, extra=extra)
    try:
        await client.submit(NewMission(name="substitution"))
        for n in range(LEGS):
            goal = {"x": 10.0, "y": 15.0 if n % 2 == 0 else 5.0}
            params = {"goal": goal, "speed": 0.2}
            await client.submit(AddSkill(robot="lru1", skill="drive_to", params=params))
        await client.submit(Sync(robot="lru1"))
        await client.submit(Control(op="run", robot="lru1"))
        # 12 sim-min: lru1 stops responding (offline); 15: lru3 asks to join
        await client.wait_for(lambda m: not client.robots["lru1"].online, 30)
        await client.wait_for(
            lambda m: "lru3" in client.robots and client.robots["lru3"].joining, 30
        )
        await client.submit(AddRobot(name="lru3", type="lru_science"))
        await client.wait_for(lambda m: client.robots["lru3"].online, 20)

        # the two actions: retire lru1, give its remaining plan to lru3
        retired = await client.submit(RetireRobot(name="lru1", reason="stopped responding"))
        plan = retired.value["to_reassign"]
        assert plan and plan[0].endswith(".2"), plan  # the interrupted drive, again
        given = await client.submit(Reassign(from_robot="lru1", to="lru3"))
        assert given.value["moved"] == plan and given.value["refused"] == {}

        await client.submit(Sync(robot="lru3"))
        await client.submit(Control(op="run", robot="lru3"))
        m = await client.wait_for(lambda m: _done(m, "lru3"), 60)
        assert all(s.status == Status.SUCCESS for s in m.tasks["lru3"])
        assert [s.id for s in m.tasks["lru3"]] == plan
        lru1 = m.tasks["lru1"]  # its log stays: what it did, and the drive it was on
        assert [s.status for s in lru1][-1] == Status.FAILURE and len(lru1) == LEGS - len(plan) + 1
        assert m.robots["lru1"].retired == "stopped responding"
        final = client.mission.model_dump(mode="json")
    finally:
        watch.close()
        await client.close()

    # whatever the journal accepted replays to the same mission
    assert stack.server is not None
    stack.server.stop()
    db = tmp_path / f"mission-{stack.endpoint.rsplit(':', 1)[1]}.db"  # Stack.start_server's
    with Journal.open(db) as journal:
        replayed, _ = journal.load()
    assert replayed is not None
    assert replayed.model_dump(mode="json") == final


def test_team_events_refuse_what_cannot_happen_and_fail_the_arm() -> None:
    from types import SimpleNamespace

    from backend.files.missions import load_mission
    from sim.team import TeamEvents

    from .conftest import MISSION

    _, library = load_mission(MISSION)
    fleet = SimpleNamespace(
        agents={"lru1": None, "lru2": None},
        library=library,
        world=SimpleNamespace(models=dict.fromkeys(("lru_science", "lru_manipulator"))),
    )
    cases = (
        ([Breakdown("lru9", 1.0)], [], "--break lru9: not a simulated robot"),
        ([], [Arrival("lru2", "lru_science", 1.0)], "--join lru2: a robot of that name"),
        ([], [Arrival("lru3", "hovercraft", 1.0)], "no robot type 'hovercraft'"),
        ([], [Arrival("lru3", "drone", 1.0)], "the world has no model for type 'drone'"),
    )
    for breaks, joins, said in cases:
        with pytest.raises(ValueError, match=said):
            TeamEvents(breaks, joins).check(fleet)
    team = TeamEvents([Breakdown("lru2", 1.0, "arm")], [])
    team.check(fleet)
    team.broken_arms.add("lru2")  # as its breakdown does
    assert team.arm_failed("lru2", "pick_stone") and not team.arm_failed("lru2", "drive_to")
