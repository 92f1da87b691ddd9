"""Building a whole mission (a file, a journal's snapshot) or saving one runs
without the cyclic garbage collector, which otherwise walked every live object
again and again while hundreds of thousands were made; it runs afterwards."""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from backend.core.bulk import gc_paused
from backend.core.model import Mission, RobotSpec, SkillInstance
from backend.files.missions import load_mission, mission_to_yaml, save_mission, validate_file
from backend.server.journal import Journal

ROOT = Path(__file__).resolve().parents[2]
LIBRARY = ROOT / "missions" / "libraries" / "mars.yaml"


def big_mission(robots: int = 4, per_robot: int = 300) -> Mission:
    m = Mission(name="big", library=str(LIBRARY))
    for r in range(robots):
        name = f"rover{r + 1}"
        m.robots[name] = RobotSpec(type="lru_manipulator")
        m.tasks[name] = [
            SkillInstance(
                id=f"{name}-{j}",
                skill="drive_to",
                label=f"waypoint {j}",
                params={"goal": {"x": j % 50, "y": r, "yaw": 0.0}, "speed": 0.5},
            )
            for j in range(1, per_robot + 1)
        ]
    m.next_skill = per_robot + 1
    return m


@contextmanager
def collections() -> Iterator[list[int]]:
    """The generations of the collections that ran inside."""
    ran: list[int] = []

    def count(phase: str, info: dict) -> None:
        if phase == "start":
            ran.append(info["generation"])

    gc.collect()  # start from a clean slate: nothing already due
    gc.callbacks.append(count)
    try:
        yield ran
    finally:
        gc.callbacks.remove(count)


def test_gc_paused_restores_the_collector_as_it_found_it():
    assert gc.isenabled()
    with gc_paused():
        assert not gc.isenabled()
        with gc_paused():
            assert not gc.isenabled()
        assert not gc.isenabled()  # the outer one decides
    assert gc.isenabled()
    with pytest.raises(RuntimeError), gc_paused():
        raise RuntimeError("a bad file")
    assert gc.isenabled()
    gc.disable()
    try:
        with gc_paused():
            pass
        assert not gc.isenabled()  # whoever disabled it keeps it so
    finally:
        gc.enable()


def test_a_mission_file_and_a_journal_load_without_collections(tmp_path):
    mission = big_mission()
    path = tmp_path / "big.yaml"
    path.write_text(mission_to_yaml(mission), encoding="utf-8")
    with Journal.open(tmp_path / "big.db") as j:
        j.snapshot(mission)

    with collections() as ran:  # the baseline: the same file, collector on
        yaml_doc = path.read_text(encoding="utf-8")
        Mission.model_validate_json(mission.model_dump_json())
        assert yaml_doc and ran, "building this many objects should trigger collections"

    with collections() as ran:
        loaded, _ = load_mission(path)
        assert validate_file(path) == []
        with Journal.open(tmp_path / "big.db") as j:
            restored, _ = j.load()
        save_mission(loaded, tmp_path / "again.yaml", library_file=LIBRARY)
    # none while building; at most one as each of the four resumes the
    # collector (building these with it on ran hundreds, some of them full)
    assert len(ran) <= 4 and 2 not in ran, ran
    assert gc.isenabled()
    assert sum(len(t) for t in loaded.tasks.values()) == 1200
    assert restored == mission


def test_a_deep_copy_equals_the_mission_and_shares_nothing_with_it():
    from datetime import UTC, datetime

    from backend.core.model import Status

    m = big_mission(robots=2, per_robot=3)
    s = m.tasks["rover1"][0]
    s.status, s.started_at = Status.RUNNING, datetime(2030, 7, 1, 8, 0, 0, 123456, tzinfo=UTC)
    s.params["speed"] = 0.1 + 0.2  # a float JSON must give back exactly
    m.find("rover2-3")  # hints are not part of the copy's content
    copy = m.copy_deep()
    assert copy == m and copy.model_dump() == m.model_dump()
    copy.tasks["rover1"][0].params["goal"]["x"] = 99
    copy.tasks["rover2"].pop()
    assert m.tasks["rover1"][0].params["goal"]["x"] == 1 and len(m.tasks["rover2"]) == 3
    assert m.find("rover2-3") is not None and copy.find("rover2-3") is None
