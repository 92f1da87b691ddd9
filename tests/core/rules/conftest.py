"""Fixtures and helpers for the operation-rules tests (`backend.core.rules.engine.Engine`).

Every engine made through the `engine` / `make_engine` fixtures is checked
after the test: each robot's list keeps the section order, skill ids are
unique, and barriers are valid (>= 2 skills of distinct robots, every member
exists, no skill in two barriers).

The helpers are plain functions here and are also offered as fixtures
(`sync`, `report`, `snapshot`, `refused`, `bring`) so test modules need no
imports from this file.
"""

from __future__ import annotations

from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest

from backend.core.checks import check_mission
from backend.core.model import RobotSpec, Status, section_problems
from backend.core.ops import Report, Sync, SyncAck
from backend.core.rules.engine import Applied, Engine, Refusal
from backend.files.missions import load_mission

ROOT = Path(__file__).resolve().parents[3]
TUTORIAL = ROOT / "missions" / "tutorial.yaml"
SAMPLE_RETURN = ROOT / "tests" / "data" / "mars_sample_return_v1.yaml"

T0 = datetime(2030, 1, 1, 12, 0, 0, tzinfo=UTC)


# -- helpers -----------------------------------------------------------------


def sync(engine: Engine, robot: str, through: str | None = None) -> Applied:
    """Synchronize `robot` (through a skill, or all idle): plan, the robot's
    acknowledgement of exactly what was sent, then release the command."""
    sent = engine.plan_sync(Sync(robot=robot, through=through))
    ids = [s.id for s in sent]
    try:
        return engine.submit(SyncAck(robot=robot, ids=ids))
    finally:
        engine.release(robot, ids)


def report(
    engine: Engine,
    robot: str,
    skill_id: str,
    status: Status | str,
    *,
    seq: int | None = None,
    **kw: Any,
) -> Applied:
    """A robot's status report with the next sequence number of that robot."""
    if seq is None:
        seq = engine.mission.report_seqs.get(robot, 0) + 1
    return engine.submit(Report(robot=robot, seq=seq, id=skill_id, status=Status(status), **kw))


def snapshot(engine: Engine) -> dict[str, Any]:
    """Everything a refused operation must leave untouched: the mission (with
    its revision) and the engine's in-flight commands and locks."""
    return {
        "mission": engine.mission.model_dump(mode="json"),
        "locked": dict(engine.locked),
        "pending": dict(engine.pending),
    }


def refused(
    engine: Engine,
    call: Callable[[], Any],
    code: str,
    *names: str,
    robot: str | None = None,
    skill: str | None = None,
    param: str | None = None,
) -> Refusal:
    """Assert `call()` is refused with `code`, that the message names every
    string in `names`, that the structured fields match when given, and that
    nothing changed."""
    before = snapshot(engine)
    with pytest.raises(Refusal) as info:
        call()
    r = info.value
    assert r.code == code, f"expected {code!r}, got {r.code!r}: {r.message}"
    assert r.message and r.message.strip(), "a refusal carries a sentence"
    for n in names:
        assert n in r.message, f"{n!r} not named in: {r.message}"
    if robot is not None:
        assert r.robot == robot, r.to_dict()
    if skill is not None:
        assert r.skill == skill, r.to_dict()
    if param is not None:
        assert r.param == param, r.to_dict()
    after = snapshot(engine)
    assert after["mission"] == before["mission"], "a refused operation changed the mission"
    assert after["mission"]["revision"] == before["mission"]["revision"]
    assert after["locked"] == before["locked"], "a refused operation changed the locks"
    assert after["pending"] == before["pending"], (
        "a refused operation changed the commands in flight"
    )
    return r


def bring(
    engine: Engine, robot: str, skill_id: str, status: Status | str, at: datetime = T0
) -> None:
    """Drive the first idle skill `skill_id` of `robot` to `status` through
    legal operations (sync, robot reports)."""
    status = Status(status)
    if status == Status.IDLE:
        return
    sync(engine, robot, through=skill_id)
    path = {
        Status.IDLE_SYNCHRONIZED: [],
        Status.SYNCHWAITING: [Status.SYNCHWAITING],
        Status.RUNNING: [Status.RUNNING],
        Status.PAUSED: [Status.RUNNING, Status.PAUSED],
        Status.SUCCESS: [Status.RUNNING, Status.SUCCESS],
        Status.FAILURE: [Status.RUNNING, Status.FAILURE],
    }[status]
    for st in path:
        report(engine, robot, skill_id, st, at=at)
    assert status_of(engine, skill_id) == status


def status_of(engine: Engine, skill_id: str) -> Status:
    found = engine.mission.find(skill_id)
    assert found is not None, f"no skill {skill_id}"
    return found[2].status


def ids(engine: Engine, robot: str) -> list[str]:
    return [s.id for s in engine.mission.tasks.get(robot, [])]


def skill(engine: Engine, skill_id: str):
    found = engine.mission.find(skill_id)
    assert found is not None, f"no skill {skill_id}"
    return found[2]


def invariant_problems(engine: Engine) -> list[str]:
    m = engine.mission
    out: list[str] = []
    for robot, task in m.tasks.items():
        if robot not in m.robots:
            out.append(f"task list for unknown robot {robot}")
        for i, why in section_problems(task):
            out.append(f"{robot}[{i}] ({task[i].id}): {why}")
    seen: dict[str, str] = {}
    for robot, task in m.tasks.items():
        for s in task:
            if s.id in seen:
                out.append(f"duplicate skill id {s.id} ({seen[s.id]} and {robot})")
            seen[s.id] = robot
    owner: dict[str, str] = {}
    for bid, b in m.barriers.items():
        if len(b.skills) < 2:
            out.append(f"barrier {bid} has fewer than two skills")
        robots: list[str] = []
        for sid in b.skills:
            if sid not in seen:
                out.append(f"barrier {bid} names missing skill {sid}")
                continue
            robots.append(seen[sid])
            if sid in owner:
                out.append(f"skill {sid} is in barriers {owner[sid]} and {bid}")
            owner[sid] = bid
        if len(set(robots)) != len(robots):
            out.append(f"barrier {bid} has two skills of one robot: {b.skills}")
        if len(set(robots)) < 2:
            out.append(f"barrier {bid} ties fewer than two robots: {b.skills}")
    return out


def assert_invariants(engine: Engine) -> None:
    problems = invariant_problems(engine)
    assert problems == [], "mission invariants broken:\n" + "\n".join(problems)


def tutorial_engine() -> Engine:
    mission, library = load_mission(TUTORIAL)
    return Engine(mission, library)


def three_robot_engine() -> Engine:
    """The tutorial plus Ardea (a drone) with one idle skill and the lander (a
    static robot) with none, built in code."""
    mission, library = load_mission(TUTORIAL)
    mission.robots["ardea"] = RobotSpec(type="drone")
    mission.tasks["ardea"] = []
    mission.robots["lander"] = RobotSpec(type="lander")
    mission.tasks["lander"] = []
    engine = Engine(mission, library)
    from backend.core.ops import AddSkill

    added = engine.submit(AddSkill(robot="ardea", skill="takeoff", label="lift off"))
    assert check_mission(engine.mission.model_copy(deep=True), library, fill=False) == []
    engine.ardea_first = added.value["id"]  # type: ignore[attr-defined]
    return engine


# -- fixtures ------------------------------------------------------------------


@pytest.fixture
def _engines() -> list[Engine]:
    return []


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    rep = outcome.get_result()
    setattr(item, f"_rules_rep_{rep.when}", rep)


@pytest.fixture(autouse=True)
def _check_invariants(request, _engines: list[Engine]):
    """After every test: the invariants hold for every engine it made (not
    checked again when the test itself already failed)."""
    yield
    rep = getattr(request.node, "_rules_rep_call", None)
    if rep is not None and rep.failed:
        return
    for e in _engines:
        assert_invariants(e)


@pytest.fixture
def make_engine(_engines: list[Engine]) -> Callable[..., Engine]:
    def make(kind: str = "tutorial") -> Engine:
        e = {"tutorial": tutorial_engine, "three": three_robot_engine}[kind]()
        _engines.append(e)
        return e

    return make


@pytest.fixture
def engine(make_engine) -> Engine:
    """An engine on missions/tutorial.yaml: lru1 [lru1-1 drive_to (goal bound
    to POI-A), lru1-2 take_science_image (target bound to POI-A)], lru2
    [lru2-1 drive_to, lru2-2 identify_stone], all idle."""
    return make_engine()


@pytest.fixture
def engine3(make_engine) -> Engine:
    """The tutorial plus ardea (one idle skill, id in `engine3.ardea_first`)
    and the lander (no skill)."""
    return make_engine("three")


@pytest.fixture(name="sync")
def _sync_fixture():
    return sync


@pytest.fixture(name="report")
def _report_fixture():
    return report


@pytest.fixture(name="snapshot")
def _snapshot_fixture():
    return snapshot


@pytest.fixture(name="refused")
def _refused_fixture():
    return refused


@pytest.fixture(name="bring")
def _bring_fixture():
    return bring


@pytest.fixture(name="ids")
def _ids_fixture():
    return ids


@pytest.fixture(name="skill")
def _skill_fixture():
    return skill


@pytest.fixture(name="status_of")
def _status_fixture():
    return status_of


@pytest.fixture(name="inv")
def _inv_fixture():
    """Check the invariants in the middle of a test."""
    return assert_invariants
