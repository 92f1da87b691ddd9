"""Contingencies in the forecast and the plan checks (backend.core.plan.branches):
the end time takes the nominal path, or the on_timeout of a skill that outlasts
its timeout; the battery is also checked on each branch's worst path."""

from __future__ import annotations

import pytest

from backend.cli.ctl.plan import timeline_json, timeline_text
from backend.core.model import Fallback, FallbackSkill, Goto, Policies, PoseMarker
from backend.core.plan.checks import run_checks
from backend.core.plan.forecast import forecast
from backend.core.plan.inputs import PlanInputs, RobotNow

from .helpers import LIBRARY, T0, mission, pose, skill


def rover_plan(first_policies: Policies, *, battery: float = 1.0, goal_x: float = 100.0):
    """r1: drive to (goal_x, 0) at 1 m/s with `first_policies`, then drive to (0, 5)."""
    first = skill("r1-1", "drive", goal=pose(goal_x, 0))
    first.policies = first_policies
    m = mission({"r1": "rover"}, {"r1": [first, skill("r1-2", "drive", goal=pose(0, 5))]})
    m.markers["Home"] = PoseMarker(pose=pose(0, 0))
    robots = {"r1": RobotNow(at=T0, x=0, y=0, battery=battery)}
    return m, PlanInputs(now=T0, robots=robots)


def test_without_a_short_timeout_the_forecast_takes_the_nominal_path():
    m, inputs = rover_plan(Policies(timeout="10m", on_failure=Goto(goto="Home")))
    f = forecast(m, LIBRARY, inputs).skill("r1-1")
    assert f is not None and f.end - f.start == pytest.approx(100)
    assert f.assumed is None  # a failure is never assumed for the end time
    assert f.battery_end == pytest.approx(0.9)
    # ...but its worst path is costed: it fails at (100, 0), then drives home
    assert f.worst is not None and (f.worst.trigger, f.worst.text) == ("failure", "goto@Home")
    assert f.worst.busy_s == pytest.approx(100) and f.worst.battery_min == pytest.approx(0.8)


def test_a_short_timeout_counts_its_goto_from_where_the_robot_stopped():
    m, inputs = rover_plan(Policies(timeout="10s", on_timeout=Goto(goto="Home")))
    fc = forecast(m, LIBRARY, inputs)
    first, second = fc.skill("r1-1"), fc.skill("r1-2")
    assert first is not None and second is not None
    # 10 s of the drive (to (10, 0)), then the goto's drive back home: 10 s
    assert first.end - first.start == pytest.approx(20)
    assert first.assumed is not None and first.assumed.text == "goto@Home"
    assert first.battery_end == pytest.approx(0.98)  # 20 m, not 100
    # the next skill starts at home, where the goto ended: 5 m to (0, 5)
    assert second.end - second.start == pytest.approx(5)
    assert fc.end == pytest.approx(T0 + 25)


@pytest.mark.parametrize(
    ("on_timeout", "takes"), [("skip", 10.0), ("halt", 10.0), ("continue", 100.0)]
)
def test_skip_and_halt_stop_at_the_timeout_continue_runs_on(on_timeout, takes):
    m, inputs = rover_plan(Policies(timeout="10s", on_timeout=on_timeout))
    f = forecast(m, LIBRARY, inputs).skill("r1-1")
    assert f is not None and f.end - f.start == pytest.approx(takes)


def test_a_fallback_that_would_exhaust_the_battery_is_a_warning():
    home = Fallback(fallback=[FallbackSkill(skill="drive", bindings={"goal": "Home"})])
    m, inputs = rover_plan(Policies(on_failure=home), battery=0.5, goal_x=400.0)
    out = run_checks(m, LIBRARY, inputs)
    (f,) = [x for x in out if x.rule == "contingency.branch_energy"]
    assert f.id == "contingency.branch_energy:r1-1/on_failure" and f.severity == "warning"
    assert "if r1-1 (drive) fails at its end, its drive@Home" in f.message
    assert "below the reserve 5%" in f.message
    # the nominal path of r1-1 itself is fine (10% left): only the branch is short
    assert not [x for x in out if x.rule == "energy.empty" and "r1-1" in x.skills]
    # a nearer drive leaves enough for the way back: no warning
    m, inputs = rover_plan(Policies(on_failure=home), battery=0.5, goal_x=200.0)
    assert not [x for x in run_checks(m, LIBRARY, inputs) if x.rule.endswith("branch_energy")]


def test_the_timeline_says_which_branch_it_assumes_and_the_worst():
    m, inputs = rover_plan(Policies(timeout="10s", on_timeout="skip", on_failure=Goto(goto="Home")))
    fc = forecast(m, LIBRARY, inputs)
    text = timeline_text(fc, m)
    line = next(ln for ln in text.splitlines() if "r1-1" in ln)
    assert "on timeout → skip (assumed: the timeout is shorter)" in line
    assert "if it fails: goto@Home +0:10, battery 98%" in line  # stopped at 10 m, back home
    data = timeline_json(fc, m)["robots"]["r1"]["skills"][0]
    assert data["assumed"]["branch"] == "skip" and data["worst"]["trigger"] == "failure"
