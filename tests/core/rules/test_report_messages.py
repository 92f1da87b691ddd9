"""The refusals of a robot's report about a skill, word for word."""

from __future__ import annotations

import pytest

from backend.core.model import Status
from backend.core.ops import Report
from backend.core.rules.engine import Refusal


def refusal(engine, rep: Report) -> tuple[str, str]:
    with pytest.raises(Refusal) as refused:
        engine.submit(rep)
    return refused.value.code, str(refused.value)


def test_a_report_on_a_skill_the_mission_lacks(engine):
    rep = Report(robot="lru1", seq=1, id="lru9-9", status=Status.RUNNING)
    assert refusal(engine, rep) == (
        "bad_report",
        "lru1 reported on skill lru9-9, which this mission does not have",
    )


def test_a_report_on_another_robots_skill(engine):
    theirs = engine.mission.find("lru2-1")[2]
    rep = Report(robot="lru1", seq=1, id="lru2-1", status=Status.RUNNING)
    assert refusal(engine, rep) == (
        "bad_report",
        f"lru1 reported on {theirs.display()}, which belongs to lru2",
    )


def test_a_report_of_an_earlier_attempt(engine, sync):
    sync(engine, "lru1")
    engine.submit(Report(robot="lru1", seq=1, id="lru1-1", status=Status.RUNNING, attempt=2))
    s = engine.mission.find("lru1-1")[2]
    rep = Report(robot="lru1", seq=2, id="lru1-1", status=Status.SUCCESS, attempt=1)
    assert refusal(engine, rep) == (
        "bad_report",
        f"lru1 reported attempt 1 of {s.display()}, which is at attempt 2",
    )
