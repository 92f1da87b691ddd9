"""Allocation hints (issue 30): robots ranked by the forecast's end and the
battery left with the skills given to them (`backend.core.plan.suggest`)."""

from __future__ import annotations

import pytest

from backend.core.model import RobotSpec
from backend.core.ops import AddRobot, AddSkill, RetireRobot
from backend.core.plan.inputs import PlanInputs, RobotNow
from backend.core.plan.suggest import suggest, taken_words
from backend.core.rules.engine import Engine
from tests.core.plan.helpers import LIBRARY, T0, FakeSite, mission, pose, skill
from tests.core.rules.conftest import tutorial_engine

NOW = 1_900_000_000.0


def _engine() -> Engine:
    e = tutorial_engine()
    e.submit(AddRobot(name="lru3", type="lru_science"))
    e.submit(AddRobot(name="lru4", type="lru_science"))
    # lru4 is busy for a long while first: lru3 ends earlier with the same skills
    for x in (0, 200, 0):  # (the first leg starts where it is: unknown, so it takes 0 s)
        e.submit(AddSkill(robot="lru4", skill="drive_to", params={"goal": {"x": x, "y": 0}}))
    return e


def test_robots_that_can_take_the_plan_are_ranked_by_their_end() -> None:
    e = _engine()
    hints = suggest(e.mission, e.library, PlanInputs(now=NOW), ["lru1-1", "lru1-2"])
    names = [h.robot for h in hints]
    assert names[:2] == ["lru3", "lru4"], hints
    lru3, lru4 = hints[0], hints[1]
    assert lru3.capable and lru3.moved == ("lru1-1", "lru1-2")
    assert lru3.end is not None and lru4.end is not None and lru3.end < lru4.end
    # lru2 (a manipulator) cannot take the science image: last, saying why
    lru2 = hints[-1]
    assert lru2.robot == "lru2" and not lru2.capable
    assert "has no skill 'take_science_image'" in lru2.refused["lru1-2"]
    assert "lru1" not in names  # their owner


def test_battery_left_breaks_a_tie_and_retired_robots_bid_nothing() -> None:
    e = tutorial_engine()
    e.mission.robots["lru3"] = RobotSpec(type="lru_science")
    e.mission.tasks["lru3"] = []
    e.mission.robots["lru4"] = RobotSpec(type="lru_science")
    e.mission.tasks["lru4"] = []
    inputs = PlanInputs(
        now=NOW, robots={"lru3": RobotNow(at=NOW, battery=0.4), "lru4": RobotNow(NOW, battery=0.9)}
    )
    hints = suggest(e.mission, e.library, inputs, ["lru1-2"])
    assert [h.robot for h in hints if h.capable][:2] == ["lru4", "lru3"]
    e.submit(RetireRobot(name="lru4", reason="broken"))
    assert "lru4" not in [h.robot for h in suggest(e.mission, e.library, inputs, ["lru1-2"])]


def test_a_skill_by_name_is_a_new_one_at_the_end_of_each_plan() -> None:
    e = _engine()
    hints = suggest(e.mission, e.library, PlanInputs(now=NOW), ["take_science_image"])
    capable = [h.robot for h in hints if h.capable]
    assert set(capable) == {"lru1", "lru3", "lru4"} and capable[-1] == "lru4"
    assert hints[-1].robot == "lru2" and "no skill" in hints[-1].refused["take_science_image"]


def test_time_out_of_coverage_is_reported_and_weighed_between_equal_ends() -> None:
    """r1's drive to (80, 0): coverage reaches 50 m from the origin. r2 at (40, 0)
    drives 10 of its 40 m in coverage, r3 at (120, 0) none: the same end, and
    r3's fuller battery counts after the time out of reach."""
    m = mission(
        {"r1": "rover", "r2": "rover", "r3": "rover"},
        {"r1": [skill("r1-1", "drive", goal=pose(80, 0))]},
    )
    robots = {
        "r2": RobotNow(at=T0, x=40.0, y=0.0, battery=0.5),
        "r3": RobotNow(at=T0, x=120.0, y=0.0, battery=0.9),
    }
    inputs = PlanInputs(now=T0, robots=robots, site=FakeSite(radius=50.0))
    r2, r3 = suggest(m, LIBRARY, inputs, ["r1-1"])
    assert (r2.robot, r3.robot) == ("r2", "r3") and r2.end == r3.end
    assert r2.out_of_coverage_s == pytest.approx(30.0, abs=3.0)  # sampled along the route
    assert r3.out_of_coverage_s == pytest.approx(40.0, abs=3.0)
    # by name: the new skill's time out of reach, from where each plan leaves the robot
    by_name = {h.robot: h for h in suggest(m, LIBRARY, inputs, ["work"])}
    assert by_name["r1"].out_of_coverage_s == 100.0  # it works where its drive ends, at 80 m
    assert by_name["r2"].out_of_coverage_s == 0.0  # at 40 m, in reach
    # no site map: unknown, not zero
    blind = suggest(m, LIBRARY, PlanInputs(now=T0, robots=robots), ["r1-1"])
    assert all(h.out_of_coverage_s is None for h in blind)
    assert [h.robot for h in blind] == ["r3", "r2"]  # then the battery decides


def test_a_robot_that_takes_more_ranks_above_one_that_ends_sooner_with_less() -> None:
    """Nobody takes everything (a barrier holds one skill): the robot that takes
    three of four ranks above one that takes one and so ends sooner."""
    from backend.core.plan.suggest import Suggestion

    most = Suggestion("lru3", ("a", "b", "c"), {"d": "held"}, end=NOW + 600, battery_end=0.8)
    least = Suggestion("ardea", ("a",), {"b": "no", "c": "no", "d": "no"}, end=NOW + 60)
    every = Suggestion("lru4", ("a", "b", "c", "d"), {}, end=NOW + 900)
    ranked = sorted([least, most, every], key=Suggestion.rank)
    assert [s.robot for s in ranked] == ["lru4", "lru3", "ardea"]


def test_a_row_says_how_much_of_the_gift_its_robot_takes():
    assert taken_words(3, 1) == "takes 3 of 4, "
    assert taken_words(3, 0) == "takes all 3, "  # why it ranks above one that takes part
    assert taken_words(1, 0) == ""  # one skill: the row is the robot taking it
