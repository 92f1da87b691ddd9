"""Plan checks: for each rule a mission that triggers it and one that does
not; deadlocks across two and three robots; ids stable; waivers attached."""

from __future__ import annotations

import pytest

from backend.core.model import ChooseRule, Chosen, Policies, Pose, PoseMarker, Waiver
from backend.core.plan.checks import RULES, run_checks
from backend.core.plan.inputs import PlanInputs, RobotNow

from .helpers import LIBRARY, T0, FakeSite, mission, pose, skill

SQUARE = [{"x": 0, "y": 0}, {"x": 10, "y": 0}, {"x": 10, "y": 10}, {"x": 0, "y": 10}]


def found(m, *, site=None, robots=None, rule=None):
    inputs = PlanInputs(now=T0, site=site, robots=robots or {}, home=(0.0, 0.0))
    out = run_checks(m, LIBRARY, inputs)
    return [f for f in out if rule is None or f.rule == rule]


def ids(findings):
    return [f.id for f in findings]


def two_rovers(r1, r2, barriers):
    return mission({"r1": "rover", "r2": "rover"}, {"r1": r1, "r2": r2}, barriers)


# -- barriers ------------------------------------------------------------------------


def test_crossed_barriers_of_two_robots_are_a_deadlock():
    m = two_rovers(
        [skill("r1-1", "meet"), skill("r1-2", "meet")],
        [skill("r2-1", "meet"), skill("r2-2", "meet")],
        {"b1": ["r1-1", "r2-2"], "b2": ["r1-2", "r2-1"]},
    )
    (f,) = found(m, rule="barrier.deadlock")
    assert f.id == "barrier.deadlock:b1+b2"
    assert f.severity == "error" and f.blocking
    assert set(f.skills) == {"r1-1", "r1-2", "r2-1", "r2-2"}
    assert "r1 must pass b1 (r1-1) before it reaches b2 (r1-2)" in f.message
    assert "r2 must pass b2 (r2-1) before it reaches b1 (r2-2)" in f.message


def test_barriers_in_the_same_order_are_no_deadlock():
    m = two_rovers(
        [skill("r1-1", "meet"), skill("r1-2", "meet")],
        [skill("r2-1", "meet"), skill("r2-2", "meet")],
        {"b1": ["r1-1", "r2-1"], "b2": ["r1-2", "r2-2"]},
    )
    assert found(m, rule="barrier.deadlock") == []


def test_a_deadlock_across_three_robots_each_pair_fine():
    m = mission(
        {"a": "rover", "b": "rover", "c": "rover"},
        {
            "a": [skill("a-1", "meet"), skill("a-2", "meet")],
            "b": [skill("b-1", "meet"), skill("b-2", "meet")],
            "c": [skill("c-1", "meet"), skill("c-2", "meet"), skill("c-3", "work")],
        },
        # a: x then y; b: y then z; c: z then x -- a cycle only through all three
        {"x": ["a-1", "c-2"], "y": ["a-2", "b-1"], "z": ["b-2", "c-1"]},
    )
    (f,) = found(m, rule="barrier.deadlock")
    assert f.id == "barrier.deadlock:x+y+z"
    for said in (
        "a must pass x (a-1) before it reaches y (a-2)",
        "b must pass y (b-1) before it reaches z (b-2)",
        "c must pass z (c-1) before it reaches x (c-2)",
    ):
        assert said in f.message
    # reorder c: z after x, and the cycle is gone
    m.tasks["c"] = [m.tasks["c"][1], m.tasks["c"][0], m.tasks["c"][2]]
    assert found(m, rule="barrier.deadlock") == []


def test_barriers_stuck_behind_a_deadlock_are_not_reported_as_one():
    m = mission(
        {"a": "rover", "b": "rover", "c": "rover"},
        {
            "a": [skill("a-1", "meet"), skill("a-2", "meet")],
            "b": [skill("b-1", "meet"), skill("b-2", "meet"), skill("b-3", "meet")],
            "c": [skill("c-1", "meet")],
        },
        {"b1": ["a-1", "b-2"], "b2": ["a-2", "b-1"], "b3": ["b-3", "c-1"]},
    )
    assert ids(found(m, rule="barrier.deadlock")) == ["barrier.deadlock:b1+b2"]


def test_a_barrier_a_partner_already_went_through_is_orphaned():
    m = two_rovers(
        [skill("r1-1", "meet", "success")],
        [skill("r2-1", "meet", "idle_synchronized")],
        {"b1": ["r1-1", "r2-1"]},
    )
    (f,) = found(m, rule="barrier.orphaned")
    assert f.id == "barrier.orphaned:b1" and f.skills == ("r2-1",)
    assert "ctl unbarrier b1" in f.message
    m.tasks["r1"][0] = skill("r1-1", "meet", "idle_synchronized")
    assert found(m, rule="barrier.orphaned") == []


# -- energy ---------------------------------------------------------------------------


def test_a_plan_emptying_the_battery_before_a_recharge_is_an_error():
    m = mission(
        {"r1": "rover"},
        {
            "r1": [
                skill("r1-1", "drive", goal=pose(400, 0)),  # 0.4
                skill("r1-2", "drive", goal=pose(0, 0)),  # 0.4: 0.2 left of 1.0
                skill("r1-3", "drive", goal=pose(300, 0)),  # 0.3: below the 0.05 reserve
                skill("r1-4", "charge"),
            ]
        },
    )
    (f,) = found(m, robots={"r1": RobotNow(at=T0, x=0, y=0, battery=1.0)}, rule="energy.empty")
    assert f.id == "energy.empty:r1-3" and f.robot == "r1"
    assert "before r1-4 recharges it" in f.message
    (w,) = found(m, robots={"r1": RobotNow(at=T0, x=0, y=0, battery=1.0)}, rule="energy.margin")
    assert w.id == "energy.margin:r1-2" and w.severity == "warning"
    # with a recharge between them, both legs fit
    m.tasks["r1"].insert(2, skill("r1-5", "charge"))
    assert (
        found(m, robots={"r1": RobotNow(at=T0, x=0, y=0, battery=1.0)}, rule="energy.empty") == []
    )


def test_energy_uses_the_battery_in_telemetry_else_assumes_a_full_one():
    m = mission({"r1": "rover"}, {"r1": [skill("r1-1", "drive", goal=pose(300, 0))]})
    assert (
        found(m, robots={"r1": RobotNow(at=T0, x=0, y=0, battery=1.0)}, rule="energy.empty") == []
    )
    (f,) = found(m, robots={"r1": RobotNow(at=T0, x=0, y=0, battery=0.3)}, rule="energy.empty")
    assert "no recharge planned" in f.message
    big = [{"x": x * 200, "y": y * 200} for x, y in ((0, 0), (1, 0), (1, 1), (0, 1))]
    m2 = mission({"d1": "drone"}, {"d1": [skill("d1-1", "survey", area=big, seconds=2000)]})
    (f,) = found(m2, rule="energy.empty")  # 1000 s of flight per battery
    assert "assuming a full battery" in f.message


# -- coverage ------------------------------------------------------------------------------


def test_a_skill_needing_the_link_planned_out_of_coverage():
    site = FakeSite(radius=50)
    m = mission(
        {"r1": "rover"},
        {"r1": [skill("r1-1", "drive", goal=pose(80, 0)), skill("r1-2", "link")]},
    )
    robots = {"r1": RobotNow(at=T0, x=0, y=0, battery=1.0)}
    (f,) = found(m, site=site, robots=robots, rule="coverage.needs_comms")
    assert f.id == "coverage.needs_comms:r1-2" and f.severity == "error"
    assert found(m, robots=robots, rule="coverage.needs_comms") == []  # no map: not checked
    m.tasks["r1"][0] = skill("r1-1", "drive", goal=pose(30, 0))
    assert found(m, site=site, robots=robots, rule="coverage.needs_comms") == []


def test_a_skill_that_pauses_out_of_comms_planned_out_of_coverage():
    site = FakeSite(radius=50)
    s = skill("r1-1", "drive", goal=pose(80, 0))
    s.policies = Policies(pause_out_of_comms=True)
    m = mission({"r1": "rover"}, {"r1": [s, skill("r1-2", "drive", goal=pose(0, 0))]})
    robots = {"r1": RobotNow(at=T0, x=0, y=0, battery=1.0)}
    (f,) = found(m, site=site, robots=robots, rule="coverage.needs_comms")
    assert "pauses out of comms" in f.message


def test_a_barrier_a_robot_waits_at_out_of_coverage_is_never_passed():
    """Issue 35: LRU1 and LRU2 out of coverage at their barrier never met; both rows stayed
    "stale" with no error. Partners meet only where they can talk."""
    site = FakeSite(radius=50)
    m = two_rovers(
        [skill("r1-1", "drive", goal=pose(80, 0)), skill("r1-2", "meet", partner="r2")],
        [skill("r2-1", "drive", goal=pose(10, 0)), skill("r2-2", "meet", partner="r1")],
        {"b1": ["r1-2", "r2-2"]},
    )
    robots = {r: RobotNow(at=T0, x=0, y=0, battery=1.0) for r in ("r1", "r2")}
    (f,) = found(m, site=site, robots=robots, rule="coverage.barrier")
    assert f.id == "coverage.barrier:b1" and f.severity == "error" and f.blocking
    assert f.skills == ("r1-2", "r2-2") and f.robot == "r1"
    assert "r1 waits at (80, 0), out of comms coverage" in f.message
    assert "deploy a Wi-Fi box" in f.message
    assert found(m, robots=robots, rule="coverage.barrier") == []  # no map: not checked
    # both in coverage: they meet
    m.tasks["r1"][0] = skill("r1-1", "drive", goal=pose(40, 0))
    assert found(m, site=site, robots=robots, rule="coverage.barrier") == []


def test_robots_within_radio_range_meet_out_of_coverage():
    site = FakeSite(radius=50)
    m = two_rovers(
        [skill("r1-1", "drive", goal=pose(80, 0)), skill("r1-2", "meet")],
        [skill("r2-1", "drive", goal=pose(85, 0)), skill("r2-2", "meet")],
        {"b1": ["r1-2", "r2-2"]},
    )
    robots = {r: RobotNow(at=T0, x=0, y=0, battery=1.0) for r in ("r1", "r2")}
    assert ids(found(m, site=site, robots=robots, rule="coverage.barrier")) == [
        "coverage.barrier:b1"
    ]
    radio = LIBRARY.model_copy(deep=True)
    radio.robot_types["rover"].radio_range_m = 10.0
    inputs = PlanInputs(now=T0, site=site, robots=robots, home=(0.0, 0.0))
    assert [f for f in run_checks(m, radio, inputs) if f.rule == "coverage.barrier"] == []


def test_a_skill_working_with_a_partner_where_they_cannot_talk():
    site = FakeSite(radius=50)
    m = two_rovers(
        [skill("r1-1", "pair", place=pose(80, 0), partner="r2")],
        [skill("r2-1", "pair", place=pose(80, 0), partner="r1")],
        {"b1": ["r1-1", "r2-1"]},
    )
    robots = {r: RobotNow(at=T0, x=0, y=0, battery=1.0) for r in ("r1", "r2")}
    found_ = found(m, site=site, robots=robots, rule="coverage.partner")
    assert ids(found_) == ["coverage.partner:r1-1/partner", "coverage.partner:r2-1/partner"]
    assert found_[0].severity == "warning"
    assert "works with r2 (partner) at (80, 0), out of comms coverage" in found_[0].message
    # the barrier itself is met in coverage (both start from the origin)
    assert found(m, site=site, robots=robots, rule="coverage.barrier") == []
    for task in m.tasks.values():
        task[0].params["place"] = pose(30, 0)
    assert found(m, site=site, robots=robots, rule="coverage.partner") == []


def test_a_robot_whose_plan_ends_out_of_coverage_is_stranded():
    site = FakeSite(radius=50)
    m = mission(
        {"r1": "rover", "base": "base"},
        {"r1": [skill("r1-1", "drive", goal=pose(80, 0))], "base": [skill("base-1", "work")]},
    )
    robots = {"r1": RobotNow(at=T0, x=0, y=0, battery=1.0)}
    (f,) = found(m, site=site, robots=robots, rule="coverage.stranded")
    assert f.id == "coverage.stranded:r1-1" and f.severity == "warning"
    m.tasks["r1"].append(skill("r1-2", "charge"))  # brings it home
    assert found(m, site=site, robots=robots, rule="coverage.stranded") == []


def test_a_synchronized_part_ending_out_of_coverage_cuts_off_the_rest():
    site = FakeSite(radius=50)
    m = mission(
        {"r1": "rover"},
        {
            "r1": [
                skill("r1-1", "drive", "idle_synchronized", goal=pose(80, 0)),
                skill("r1-2", "drive", goal=pose(0, 0)),
            ]
        },
    )
    robots = {"r1": RobotNow(at=T0, x=0, y=0, battery=1.0)}
    (f,) = found(m, site=site, robots=robots, rule="coverage.cut_off")
    assert f.id == "coverage.cut_off:r1-1"
    m.tasks["r1"][1] = skill("r1-2", "drive", "idle_synchronized", goal=pose(0, 0))
    assert found(m, site=site, robots=robots, rule="coverage.cut_off") == []


# -- terrain -------------------------------------------------------------------------------


def test_goals_on_impassable_and_unexplored_ground_and_without_a_route():
    site = FakeSite(radius=500, rocks={(20, 0)}, unexplored={(0, 30)}, walls=True)
    m = mission(
        {"r1": "rover", "d1": "drone"},
        {
            "r1": [
                skill("r1-1", "drive", goal=pose(20, 0)),
                skill("r1-2", "drive", goal=pose(0, 30)),
                skill("r1-4", "drive", goal=pose(10, 10)),
                skill("r1-3", "drive", goal=pose(150, 0)),
            ],
            "d1": [skill("d1-1", "fly", goal={"x": 20, "y": 0})],  # flying over rocks is fine
        },
    )
    robots = {"r1": RobotNow(at=T0, x=0, y=0, battery=1.0)}
    out = found(m, site=site, robots=robots)
    assert "terrain.impassable:r1-1/goal" in ids(out)
    assert "terrain.unexplored:r1-2/goal" in ids(out)
    assert "terrain.no_route:r1-3/goal" in ids(out)
    assert not any("r1-4" in i or "d1-1" in i for i in ids(out) if i.startswith("terrain"))
    assert [f for f in found(m, robots=robots) if f.rule.startswith("terrain")] == []


def test_a_goal_chosen_on_board_is_an_estimate_said_so_not_judged_by_the_map():
    site = FakeSite(radius=500, rocks={(20, 0)})
    to_choose = skill("r1-1", "drive", goal=pose(20, 0))
    to_choose.bindings = {"goal": "R1"}
    m = mission({"r1": "rover"}, {"r1": [to_choose]})
    m.markers["R1"] = PoseMarker(pose=Pose(x=20, y=0), choose=ChooseRule())
    robots = {"r1": RobotNow(at=T0, x=0, y=0, battery=1.0)}
    out = found(m, site=site, robots=robots)
    (said,) = [f for f in out if f.rule == "marker.chosen_on_board"]
    assert said.id == "marker.chosen_on_board:r1-1/goal" and said.severity == "warning"
    assert "chooses on board (R1, goal)" in said.message and "estimate" in said.message
    assert not [f for f in out if f.rule.startswith("terrain")]  # the estimate is no goal
    # once a robot chose it, it is a goal like any other
    m.markers["R1"].chosen = Chosen(robot="r1", skill="r1-1")
    out = found(m, site=site, robots=robots)
    assert "terrain.impassable:r1-1/goal" in ids(out)
    assert not [f for f in out if f.rule == "marker.chosen_on_board"]


# -- parameters ----------------------------------------------------------------------------


def test_a_partner_parameter_naming_its_own_robot_or_one_outside_the_barrier():
    m = two_rovers(
        [skill("r1-1", "meet", partner="r1"), skill("r1-2", "meet", partner="r2")],
        [skill("r2-1", "meet", partner="r1"), skill("r2-2", "meet", partner="r1")],
        {"b1": ["r1-2", "r2-1"]},
    )
    out = found(m)
    assert "params.self_reference:r1-1/partner" in ids(out)
    assert "params.partner_apart:r2-2/partner" in ids(out)
    assert not any(i.endswith(("r1-2/partner", "r2-1/partner")) for i in ids(out))


def test_areas_without_a_surface_or_with_crossing_edges():
    flat = [{"x": 0, "y": 0}, {"x": 10, "y": 0}, {"x": 20, "y": 0}]
    bow = [{"x": 0, "y": 0}, {"x": 10, "y": 10}, {"x": 10, "y": 0}, {"x": 0, "y": 10}]
    m = mission(
        {"r1": "rover"},
        {
            "r1": [
                skill("r1-1", "survey", area=flat),
                skill("r1-2", "survey", area=bow),
                skill("r1-3", "survey", area=SQUARE),
            ]
        },
    )
    out = ids(found(m))
    assert "params.flat_area:r1-1/area" in out
    assert "params.crossed_area:r1-2/area" in out
    assert not any("r1-3" in i for i in out)


def test_a_recharge_to_a_level_below_the_battery_then():
    m = mission({"r1": "rover"}, {"r1": [skill("r1-1", "charge", level=0.5)]})
    robots = {"r1": RobotNow(at=T0, x=0, y=0, battery=0.8)}
    (f,) = found(m, robots=robots, rule="params.useless_charge")
    assert f.id == "params.useless_charge:r1-1"
    robots = {"r1": RobotNow(at=T0, x=0, y=0, battery=0.3)}
    assert found(m, robots=robots, rule="params.useless_charge") == []


# -- the table ------------------------------------------------------------------------------


def test_finished_skills_are_never_checked():
    m = mission({"r1": "rover"}, {"r1": [skill("r1-1", "meet", "success", partner="r1")]})
    assert found(m) == []


def test_every_rule_has_a_stable_dotted_name_and_a_severity():
    names = [r.rule for r in RULES]
    assert len(names) == len(set(names))
    for r in RULES:
        family, _, what = r.rule.partition(".")
        assert family and what and r.severity in ("warning", "error") and r.summary


def test_a_waiver_is_attached_to_its_finding_and_stops_it_blocking():
    m = two_rovers(
        [skill("r1-1", "meet"), skill("r1-2", "meet")],
        [skill("r2-1", "meet"), skill("r2-2", "meet")],
        {"b1": ["r1-1", "r2-2"], "b2": ["r1-2", "r2-1"]},
    )
    m.waivers["barrier.deadlock:b1+b2"] = Waiver(reason="we stop them by hand")
    (f,) = found(m, rule="barrier.deadlock")
    assert f.waiver is not None and not f.blocking


@pytest.mark.parametrize("rule", [r.rule for r in RULES])
def test_errors_come_before_warnings(rule):
    m = mission({"r1": "rover"}, {"r1": [skill("r1-1", "meet", partner="r1")]})
    out = found(m)
    sev = [f.severity for f in out]
    assert sev == sorted(sev, key=lambda s: s != "error")


def test_docs_plan_md_lists_every_rule_with_its_severity():
    from pathlib import Path

    text = (Path(__file__).resolve().parents[3] / "docs" / "plan.md").read_text()
    for r in RULES:
        assert f"| `{r.rule}` | {r.severity} |" in text, r.rule


# -- contingencies ---------------------------------------------------------------------------


def test_a_timeout_the_forecast_cannot_meet_and_a_rally_point_on_rocks():
    from backend.core.model import Goto, PoseMarker

    site = FakeSite(radius=500, rocks={(20, 0)})
    slow = skill("r1-1", "drive", goal=pose(100, 0))
    slow.policies = Policies(timeout="10s", on_timeout="skip")
    roomy = skill("r1-2", "drive", goal=pose(0, 0))
    roomy.policies = Policies(timeout="10h", on_failure=Goto(goto="Rocks"))
    m = mission({"r1": "rover"}, {"r1": [slow, roomy]})
    m.markers["Rocks"] = PoseMarker(pose=pose(20, 0))
    robots = {"r1": RobotNow(at=T0, x=0, y=0, battery=1.0)}
    out = found(m, site=site, robots=robots)
    contingency = [f for f in out if f.rule.startswith("contingency")]
    assert ids(contingency) == [
        "contingency.goto_impassable:r1-2/on_failure",
        "contingency.timeout_short:r1-1/timeout",
    ]
    assert "longer than its timeout 10s" in contingency[1].message
    # without a map only the timeout is checked
    assert ids(found(m, robots=robots, rule="contingency.goto_impassable")) == []


def test_skills_waiting_for_each_other_through_after_are_a_deadlock():
    a1, a2 = skill("r1-1", "drive", goal=pose(1, 0)), skill("r1-2", "drive", goal=pose(2, 0))
    b1, b2 = skill("r2-1", "drive", goal=pose(1, 1)), skill("r2-2", "drive", goal=pose(2, 1))
    a1.policies = Policies(after="r2-2")  # r1 waits for r2's second skill...
    b1.policies = Policies(after="r1-2")  # ...and r2 for r1's second: neither starts
    m = two_rovers([a1, a2], [b1, b2], {})
    (f,) = found(m, rule="contingency.after_deadlock")
    assert f.id == "contingency.after_deadlock:r1-1+r2-1" and f.blocking
    # one way round is fine, and so is an after across a barrier the other robot reaches later
    b1.policies = Policies()
    assert found(m, rule="contingency.after_deadlock") == []
    c1, c2 = skill("r1-1", "drive", goal=pose(1, 0)), skill("r1-2", "drive", goal=pose(2, 0))
    d1, d2 = skill("r2-1", "drive", goal=pose(1, 1)), skill("r2-2", "drive", goal=pose(2, 1))
    c2.policies = Policies(after="r2-1")
    m = two_rovers([c1, c2], [d1, d2], {"b1": ["r1-1", "r2-2"]})
    assert found(m, rule="contingency.after_deadlock") == []
