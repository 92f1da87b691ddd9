"""Predictions: each skill's start and end, barrier waits, battery and
coverage along the plan, ends per robot and for the mission, critical path."""

from __future__ import annotations

import pytest

from backend.core.plan.forecast import Forecaster, forecast
from backend.core.plan.inputs import LinkModel, PlanInputs, RobotNow

from .helpers import LIBRARY, T0, FakeSite, mission, pose, skill


def times(fc, sid):
    f = fc.skill(sid)
    assert f is not None, f"no prediction for {sid}"
    return round(f.start - T0, 3), round(f.end - T0, 3)


def rover_at(x=0.0, y=0.0, battery=1.0, **kw):
    return RobotNow(at=T0, x=x, y=y, battery=battery, **kw)


def test_queued_skills_follow_each_other_with_travel_from_the_robots_speed():
    m = mission(
        {"r1": "rover"},
        {
            "r1": [
                skill("r1-1", "drive", "idle_synchronized", goal=pose(30, 40), speed=0.5),
                skill("r1-2", "work", "idle_synchronized", seconds=20),
                skill("r1-3", "drive", "idle_synchronized", goal=pose(30, 0)),  # speed_mps 1.0
            ]
        },
    )
    fc = forecast(m, LIBRARY, PlanInputs(now=T0, robots={"r1": rover_at()}))
    assert times(fc, "r1-1") == (0, 100)  # 50 m at 0.5 m/s
    assert times(fc, "r1-2") == (100, 120)
    assert times(fc, "r1-3") == (120, 160)  # 40 m at the type's 1 m/s
    assert fc.robots["r1"].end == T0 + 160
    assert fc.end == T0 + 160
    assert fc.critical_path() == ["r1-1", "r1-2", "r1-3"]
    assert fc.critical_robot == "r1"


def test_the_route_length_comes_from_the_site_map_for_rovers_only():
    site = FakeSite(detour=1.5)
    m = mission(
        {"r1": "rover", "d1": "drone"},
        {
            "r1": [skill("r1-1", "drive", "idle_synchronized", goal=pose(100, 0))],
            "d1": [skill("d1-1", "fly", "idle_synchronized", goal={"x": 100, "y": 0, "z": 0})],
        },
    )
    robots = {"r1": rover_at(), "d1": rover_at()}
    fc = forecast(m, LIBRARY, PlanInputs(now=T0, robots=robots, site=site))
    assert times(fc, "r1-1") == (0, 150)  # 150 m of route at 1 m/s
    assert times(fc, "d1-1") == (0, 60)  # 10 s + a straight 100 m at 2 m/s


def test_the_active_skill_ends_when_its_telemetry_says_and_never_before_now():
    m = mission(
        {"r1": "rover"},
        {
            "r1": [
                skill("r1-1", "work", "running", seconds=100),
                skill("r1-2", "work", "idle_synchronized", seconds=10),
            ]
        },
    )
    tele = rover_at(skill="r1-1", progress=0.5, eta_s=42.0)
    fc = forecast(m, LIBRARY, PlanInputs(now=T0, robots={"r1": tele}))
    assert times(fc, "r1-1") == (-10, 42)
    assert times(fc, "r1-2") == (42, 52)
    late = forecast(m, LIBRARY, PlanInputs(now=T0 + 60, robots={"r1": tele}))
    assert times(late, "r1-1")[1] == 60  # overdue: ends now at the earliest
    # no telemetry: started 10 s ago, the model says 100 s
    fc = forecast(m, LIBRARY, PlanInputs(now=T0))
    assert times(fc, "r1-1") == (-10, 90)


def test_a_paused_skill_ends_as_if_resumed_now():
    m = mission({"r1": "rover"}, {"r1": [skill("r1-1", "work", "paused", seconds=100)]})
    tele = rover_at(skill="r1-1", progress=0.25)
    fc = forecast(m, LIBRARY, PlanInputs(now=T0, robots={"r1": tele}))
    assert times(fc, "r1-1")[1] == 75


def test_unsynchronized_skills_start_no_earlier_than_the_link_delivers_them():
    m = mission(
        {"r1": "rover"},
        {
            "r1": [
                skill("r1-1", "work", "idle_synchronized", seconds=10),
                skill("r1-2", "work", seconds=10),
            ]
        },
    )
    link = LinkModel(one_way_s=600)
    fc = forecast(m, LIBRARY, PlanInputs(now=T0, link=link))
    assert times(fc, "r1-1") == (0, 10)  # on the robot already
    assert times(fc, "r1-2") == (600, 610)  # a sync sent now arrives in 10 minutes
    assert fc.skill("r1-2").after is None  # the link, not r1-1, decides it
    windows = LinkModel(one_way_s=60, windows=((T0 + 1000, T0 + 2000),))
    fc = forecast(m, LIBRARY, PlanInputs(now=T0, links={"r1": windows}))
    assert times(fc, "r1-2") == (1060, 1070)  # next contact, then the delay


def test_a_robot_halted_after_a_failure_needs_a_run_command_first():
    m = mission(
        {"r1": "rover"},
        {
            "r1": [
                skill("r1-1", "work", "failure", seconds=10),
                skill("r1-2", "work", "idle_synchronized", seconds=10),
            ]
        },
    )
    fc = forecast(m, LIBRARY, PlanInputs(now=T0, link=LinkModel(one_way_s=30)))
    assert times(fc, "r1-2") == (30, 40)
    assert fc.robots["r1"].halted


def test_barrier_partners_start_together_and_the_early_one_waits():
    m = mission(
        {"r1": "rover", "r2": "rover"},
        {
            "r1": [
                skill("r1-1", "work", "idle_synchronized", seconds=100),
                skill("r1-2", "meet", "idle_synchronized", partner="r2"),
            ],
            "r2": [
                skill("r2-1", "work", "idle_synchronized", seconds=30),
                skill("r2-2", "meet", "idle_synchronized", partner="r1"),
                skill("r2-3", "work", "idle_synchronized", seconds=5),
            ],
        },
        {"b1": ["r1-2", "r2-2"]},
    )
    fc = forecast(m, LIBRARY, PlanInputs(now=T0))
    assert times(fc, "r1-2") == (100, 150)
    assert times(fc, "r2-2") == (100, 150)
    assert fc.skill("r2-2").wait_s == 70
    assert fc.skill("r1-2").wait_s == 0
    assert fc.skill("r2-2").barrier == "b1"
    assert times(fc, "r2-3") == (150, 155)
    # r2 ends last, but r1's first skill set the barrier: the critical path crosses over
    assert fc.critical_path() == ["r1-1", "r2-2", "r2-3"]
    assert fc.critical_robot == "r2"


def test_a_skill_waiting_at_its_barrier_waits_from_now():
    m = mission(
        {"r1": "rover", "r2": "rover"},
        {
            "r1": [skill("r1-1", "meet", "synchwaiting", partner="r2")],
            "r2": [
                skill("r2-1", "work", "running", seconds=40),
                skill("r2-2", "meet", "idle_synchronized", partner="r1"),
            ],
        },
        {"b1": ["r1-1", "r2-2"]},
    )
    fc = forecast(m, LIBRARY, PlanInputs(now=T0))
    assert times(fc, "r1-1") == (30, 80)  # r2-1 started 10 s ago, 40 s long
    assert fc.skill("r1-1").ready == T0


def test_skills_behind_a_deadlock_have_no_prediction_and_the_mission_no_end():
    m = mission(
        {"r1": "rover", "r2": "rover"},
        {
            "r1": [skill("r1-1", "meet"), skill("r1-2", "meet")],
            "r2": [skill("r2-1", "meet"), skill("r2-2", "meet")],
        },
        {"b1": ["r1-1", "r2-2"], "b2": ["r1-2", "r2-1"]},
    )
    fc = forecast(m, LIBRARY, PlanInputs(now=T0))
    assert fc.skill("r1-1") is None and fc.skill("r2-2") is None
    assert fc.end is None
    assert fc.robots["r1"].blocked_at == "r1-1"
    assert fc.robots["r2"].blocked_at == "r2-1"


def test_battery_along_the_plan_drains_with_distance_and_work_and_charges_at_home():
    m = mission(
        {"r1": "rover"},
        {
            "r1": [
                skill("r1-1", "drive", goal=pose(100, 0)),  # 100 m: 0.1
                skill("r1-2", "work", seconds=1000),  # 0.0001/s: 0.1
                skill("r1-3", "charge", level=0.9),  # 100 m home (0.1), then charge
            ]
        },
    )
    inputs = PlanInputs(now=T0, robots={"r1": rover_at(battery=0.5)}, home=(0.0, 0.0))
    fc = forecast(m, LIBRARY, inputs)
    f1, f2, f3 = (fc.skill(f"r1-{i}") for i in (1, 2, 3))
    assert (f1.battery_start, round(f1.battery_end, 6)) == (0.5, 0.4)
    assert round(f2.battery_end, 6) == 0.3
    assert round(f3.battery_min, 6) == 0.2 and f3.battery_end == 0.9
    # 100 s home at 1 m/s, then 0.7 at 1 % per second
    assert times(fc, "r1-3") == (1100, 1270)
    assert not fc.robots["r1"].battery_assumed
    assumed = forecast(m, LIBRARY, PlanInputs(now=T0))
    assert assumed.robots["r1"].battery_assumed
    assert assumed.skill("r1-1").battery_start == 1.0


def test_spans_out_of_coverage_are_laid_on_the_clock():
    site = FakeSite(radius=50)
    m = mission(
        {"r1": "rover"},
        {
            "r1": [
                skill("r1-1", "drive", goal=pose(100, 0)),  # out from 50 m on
                skill("r1-2", "work", seconds=20),  # out there
                skill("r1-3", "drive", goal=pose(0, 0)),  # back in at 50 m
            ]
        },
    )
    fc = forecast(m, LIBRARY, PlanInputs(now=T0, robots={"r1": rover_at()}, site=site))
    ((a, b),) = fc.skill("r1-1").out_of_coverage
    assert 48 <= a - T0 <= 53 and b - T0 == pytest.approx(100)
    assert [(x - T0, y - T0) for x, y in fc.skill("r1-2").out_of_coverage] == [(100, 120)]
    ((a, b),) = fc.skill("r1-3").out_of_coverage
    assert a - T0 == pytest.approx(120) and 167 <= b - T0 <= 172


def test_sim_speed_turns_robot_seconds_into_wall_seconds():
    m = mission({"r1": "rover"}, {"r1": [skill("r1-1", "work", "idle_synchronized", seconds=100)]})
    fc = forecast(m, LIBRARY, PlanInputs(now=T0, speed=10.0))
    assert times(fc, "r1-1") == (0, 10)


def test_the_forecaster_recomputes_only_what_an_event_touched():
    m = mission(
        {"r1": "rover", "r2": "rover"},
        {
            "r1": [skill("r1-1", "drive", goal=pose(10, 0)), skill("r1-2", "work", seconds=5)],
            "r2": [skill("r2-1", "drive", goal=pose(0, 20))],
        },
    )
    f = Forecaster(LIBRARY)
    inputs = PlanInputs(now=T0, robots={"r1": rover_at(), "r2": rover_at()})
    first = f.forecast(m, inputs)
    # r1-2 is replaced (as apply_events does on every change): r1's course only
    m.tasks["r1"][1] = m.tasks["r1"][1].model_copy(update={"params": {"seconds": 50.0}})
    second = f.forecast(m, inputs)
    assert second.tracks["r2"].course is first.tracks["r2"].course
    assert second.tracks["r1"].course is not first.tracks["r1"].course
    assert second.tracks["r1"].course.steps[0].leg is first.tracks["r1"].course.steps[0].leg
    assert times(second, "r1-2") == (10, 60)
    # a telemetry sample of r2 recomputes r2's course, not r1's
    moved = PlanInputs(now=T0 + 1, robots={"r1": rover_at(), "r2": rover_at(y=10)})
    third = f.forecast(m, moved)
    assert third.tracks["r1"].course is second.tracks["r1"].course
    assert times(third, "r2-1") == (1, 11)


@pytest.mark.parametrize("robots", [{}, {"r1": rover_at(x=5)}])
def test_the_same_inputs_give_the_same_forecast(robots):
    m = mission({"r1": "rover"}, {"r1": [skill("r1-1", "drive", goal=pose(10, 0))]})
    a = forecast(m, LIBRARY, PlanInputs(now=T0, robots=robots))
    b = Forecaster(LIBRARY).forecast(m, PlanInputs(now=T0, robots=robots))
    assert a.skill("r1-1") == b.skill("r1-1")


def test_an_area_skill_ends_once_mapped_for_a_robot_type_with_a_survey_rate():
    square = [{"x": 0, "y": 0}, {"x": 10, "y": 0}, {"x": 10, "y": 10}, {"x": 0, "y": 10}]
    m = mission(
        {"d1": "drone", "d2": "drone", "r1": "rover"},
        {
            "d1": [skill("d1-1", "survey", "idle_synchronized", area=square, seconds=60)],
            "d2": [skill("d2-1", "survey", "idle_synchronized", area=square, seconds=60)],
            "r1": [skill("r1-1", "survey", "idle_synchronized", area=square, seconds=60)],
        },
    )
    robots = {"d1": rover_at(5, 5), "d2": rover_at(-20, 5), "r1": rover_at(5, 5)}
    fc = forecast(m, LIBRARY, PlanInputs(now=T0, robots=robots))
    assert times(fc, "d1-1") == (0, 10)  # 100 m2 at 10 m2/s from inside
    assert times(fc, "d2-1") == (0, 20)  # 20 m to its edge at 2 m/s first
    assert times(fc, "r1-1") == (0, 60)  # no survey rate: its time parameter
    assert fc.skill("d1-1").battery_end == pytest.approx(0.99)  # and only that long in the air


def test_a_window_of_time_yields_only_the_skills_in_it():
    m = mission(
        {"r1": "rover"},
        {"r1": [skill(f"r1-{i}", "work", "idle_synchronized", seconds=10) for i in range(100)]},
    )
    fc = forecast(m, LIBRARY, PlanInputs(now=T0))
    assert [f.id for f in fc.window("r1", T0 + 205, T0 + 231)] == [
        "r1-20",
        "r1-21",
        "r1-22",
        "r1-23",
    ]
    assert [f.id for f in fc.window("r1", T0 + 2000, T0 + 3000)] == []
    assert [f.id for f in fc.window("nobody", T0, T0 + 10)] == []
