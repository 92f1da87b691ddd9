"""The now-cast: a robot's probable present from its last report and its course."""

from __future__ import annotations

from backend.core.plan.forecast import Forecaster
from backend.core.plan.inputs import PlanInputs, RobotNow
from backend.core.plan.nowcast import nowcast, nowcasts

from .helpers import LIBRARY, T0, mission, pose, skill


def _course(m, robot_now):
    inputs = PlanInputs(now=T0, robots={"r1": robot_now})
    return Forecaster(LIBRARY).course(m, "r1", inputs)


def _driving():
    return mission(
        {"r1": "rover"},
        {
            "r1": [
                skill("r1-1", "drive", "running", goal=pose(100, 0), speed=1.0),
                skill("r1-2", "work", "idle_synchronized", seconds=20),
                skill("r1-3", "drive", "idle", goal=pose(0, 0)),  # not on the robot
            ]
        },
    )


def test_between_reports_it_moves_along_the_route_and_on_to_the_next_skill():
    m = _driving()
    now = RobotNow(at=T0, x=0.0, y=0.0, battery=1.0, skill="r1-1", progress=0.0)
    c = _course(m, now)
    mid = nowcast(c, m, T0 + 40)
    assert mid is not None and mid.skill == "r1-1"
    assert (round(mid.x, 3), round(mid.y, 3)) == (40.0, 0.0)  # 40 s at 1 m/s
    assert round(mid.progress, 3) == 0.4 and mid.age_s == 40
    assert mid.battery is not None and mid.battery < 1.0
    later = nowcast(c, m, T0 + 110)  # the drive took 100 s: 10 s into the work
    assert later is not None and later.skill == "r1-2" and round(later.progress, 3) == 0.5
    assert (later.x, later.y) == (100.0, 0.0)
    # at a sim's speed robot seconds pass faster
    assert nowcast(c, m, T0 + 4, speed=10).x == mid.x


def test_it_stops_where_the_robot_would_wait():
    m = _driving()
    now = RobotNow(at=T0, x=0.0, y=0.0, battery=1.0, skill="r1-1", progress=0.0)
    end = nowcast(_course(m, now), m, T0 + 1000)
    assert end is not None and end.skill is None and end.held == "queue end"
    assert (end.x, end.y) == (100.0, 0.0)  # r1-3 is not synchronized: it never goes
    halted = RobotNow(at=T0, x=5.0, y=0.0, battery=0.9, mode="halted")
    still = nowcast(_course(m, halted), m, T0 + 500)
    assert still is not None and still.held == "halted" and (still.x, still.battery) == (5.0, 0.9)


def test_the_robots_eta_sets_how_long_its_active_skill_lasts():
    m = _driving()
    now = RobotNow(at=T0, x=0.0, y=0.0, battery=1.0, skill="r1-1", progress=0.5, eta_s=200)
    half = nowcast(_course(m, now), m, T0 + 100)
    assert half is not None and half.skill == "r1-1" and round(half.progress, 3) == 0.75


def test_without_telemetry_there_is_no_nowcast():
    m = _driving()
    assert nowcast(Forecaster(LIBRARY).course(m, "r1", PlanInputs(now=T0)), m, T0) is None


def test_a_pending_sync_and_run_count_from_when_they_reach_the_robot():
    from datetime import UTC, datetime

    from backend.core.model import Enqueue, Run, UplinkCommand
    from backend.core.plan.inputs import LinkModel

    m = mission(
        {"r1": "rover"},
        {"r1": [skill("r1-1", "drive", "idle", goal=pose(100, 0), speed=1.0)]},
    )
    sent = datetime.fromtimestamp(T0, UTC)
    m.uplink["r1"] = [
        UplinkCommand(
            id=1,
            robot="r1",
            seq=1,
            op="sync",
            command=Enqueue(skills=[]),
            skills=["r1-1"],
            state="sent",
            created=sent,
            sent=sent,
        ),
        UplinkCommand(
            id=2, robot="r1", seq=2, op="run", command=Run(), state="sent", created=sent, sent=sent
        ),
    ]
    idle = RobotNow(at=T0, x=0.0, y=0.0, battery=1.0, mode="idle")
    c = _course(m, idle)
    link = LinkModel(one_way_s=10.0)
    waiting = nowcast(c, m, T0 + 5, link=link)
    assert waiting is not None and waiting.skill is None and waiting.held == "waiting"
    moving = nowcast(c, m, T0 + 50, link=link)  # it got both at T0 + 10: 40 s of driving
    assert moving is not None and moving.skill == "r1-1" and round(moving.x, 3) == 40.0
    assert nowcast(c, m, T0 + 50).x == 50.0  # no delay: from the basis on


def test_a_barrier_passes_when_every_partner_gets_there():
    m = mission(
        {"r1": "rover", "r2": "rover"},
        {
            "r1": [
                skill("r1-1", "work", "running", seconds=10),
                skill("r1-2", "work", "idle_synchronized", seconds=10),
            ],
            "r2": [
                skill("r2-1", "work", "running", seconds=50),
                skill("r2-2", "work", "idle_synchronized", seconds=10),
            ],
        },
        barriers={"b1": ["r1-2", "r2-2"]},
    )
    at0 = {
        r: RobotNow(at=T0, x=0.0, y=0.0, battery=1.0, skill=f"{r}-1", progress=0.0)
        for r in m.robots
    }
    inputs = PlanInputs(now=T0, robots=at0)
    f = Forecaster(LIBRARY)
    courses = {r: f.course(m, r, inputs) for r in m.robots}
    early = nowcasts(courses, m, T0 + 30)
    assert early["r1"].skill is None and early["r1"].held == "waiting"  # for r2
    late = nowcasts(courses, m, T0 + 55)
    assert late["r1"].skill == "r1-2" and late["r2"].skill == "r2-2"  # both from T0 + 50
    assert round(late["r1"].progress, 3) == 0.5
    # told nothing of its partner, a robot stays at the barrier
    assert nowcast(courses["r1"], m, T0 + 55).held == "barrier"
