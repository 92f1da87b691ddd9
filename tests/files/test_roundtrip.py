"""Mission files: load -> save -> load is lossless, and saved YAML is stable
and readable."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import pytest
import yaml

from backend.core.library import Library
from backend.core.model import Mission, Policies, Pose, PoseMarker, Position, Status
from backend.core.ops import (
    AddBarrier,
    AddSkill,
    EditSkill,
    MarkerAdd,
    MarkerDelete,
    MarkerMove,
    MoveSkill,
    Report,
    Sync,
    SyncAck,
)
from backend.core.rules.engine import Engine
from backend.files.missions import library_path, load_mission, save_mission, validate_file

REPO = Path(__file__).resolve().parents[2]
MISSIONS = sorted(REPO.glob("missions/*.yaml"))
LIBRARY = REPO / "missions" / "libraries" / "mars.yaml"
T0 = datetime(2025, 3, 4, 5, 6, 7, tzinfo=UTC)


def round_trip(m: Mission, path: Path, library_file: Path) -> tuple[Mission, str]:
    save_mission(m, path, library_file=library_file)
    text = path.read_text(encoding="utf-8")
    loaded, _ = load_mission(path)
    return loaded, text


def assert_same(loaded: Mission, original: Mission, saved: Path, library_file: Path) -> None:
    # the library reference is rewritten relative to the new file: same library
    assert library_path(saved, loaded.library) == library_file.resolve()
    expected = original.model_copy(update={"library": loaded.library})
    if loaded != expected:
        a, b = loaded.model_dump(mode="json"), expected.model_dump(mode="json")
        diff = {k: (a[k], b[k]) for k in a if a[k] != b[k]}
        pytest.fail(f"round trip changed the mission (loaded, original): {diff}")


def sync_and_ack(e: Engine, robot: str, through: str | None = None) -> list[str]:
    ids = [s.id for s in e.plan_sync(Sync(robot=robot, through=through))]
    e.submit(SyncAck(robot=robot, ids=ids))
    e.release(robot, ids)
    return ids


class Reporter:
    def __init__(self, e: Engine):
        self.e, self.seq = e, {}

    def __call__(self, robot: str, sid: str, status: str, info: str = "") -> None:
        self.seq[robot] = self.seq.get(robot, 0) + 1
        self.e.submit(
            Report(
                robot=robot, seq=self.seq[robot], id=sid, status=Status(status), info=info, at=T0
            )
        )


# -- shipped missions -------------------------------------------------------------------


@pytest.mark.parametrize("src", MISSIONS, ids=lambda p: p.name)
def test_shipped_mission_round_trip(src: Path, tmp_path: Path):
    m, _ = load_mission(src)
    lib_file = library_path(src, m.library)
    out = tmp_path / "sub" / src.name
    out.parent.mkdir()
    loaded, _ = round_trip(m, out, lib_file)
    assert_same(loaded, m, out, lib_file)


@pytest.mark.parametrize("src", MISSIONS, ids=lambda p: p.name)
def test_save_is_stable(src: Path, tmp_path: Path):
    m, _ = load_mission(src)
    lib_file = library_path(src, m.library)
    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    save_mission(m, a, library_file=lib_file)
    save_mission(m, b, library_file=lib_file)
    assert a.read_text() == b.read_text()
    # what was saved, loaded and saved again is the same text
    again, _ = load_mission(a)
    save_mission(again, b, library_file=lib_file)
    assert a.read_text() == b.read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.yaml", "b.yaml"]  # no temp file left


def test_a_failed_save_leaves_no_temporary_file(tmp_path: Path):
    m, _ = load_mission(MISSIONS[0])
    target = tmp_path / "mission.yaml"
    target.mkdir()  # the final rename fails, after the temporary file was written
    with pytest.raises(OSError):
        save_mission(m, target)
    assert [p.name for p in tmp_path.iterdir()] == ["mission.yaml"]


@pytest.mark.parametrize("src", MISSIONS, ids=lambda p: p.name)
def test_saved_yaml_is_readable(src: Path, tmp_path: Path):
    m, _ = load_mission(src)
    out = tmp_path / "m.yaml"
    save_mission(m, out, library_file=library_path(src, m.library))
    text = out.read_text(encoding="utf-8")
    assert text.startswith("format: missionctl/mission@1\n")
    assert "!!" not in text and "&id" not in text and "*id" not in text  # no tags, no anchors
    data = yaml.safe_load(text)
    # top-level keys in the model's order
    order = list(Mission.model_fields)
    keys = list(data)
    assert keys == sorted(keys, key=order.index)
    assert keys[:3] == ["format", "name", "library"]
    for task in data.get("tasks", {}).values():
        for item in task:
            assert list(item)[:2] == ["id", "skill"]
            assert "status" not in item  # idle, the default, is left out
            assert "policies" not in item and "attempt" not in item
    # a pose reads on one line
    assert any(line.strip().startswith(("pose: {x:", "goal: {x:")) for line in text.splitlines())
    # and the saved file is itself valid
    assert validate_file(out) == []


def test_saved_file_is_the_source_reordered_not_reinvented(tmp_path: Path):
    """Every robot, marker, skill and barrier of the source is in the saved file."""
    src = REPO / "tests" / "data" / "mars_sample_return_v1.yaml"
    source = yaml.safe_load(src.read_text())
    m, _ = load_mission(src)
    out = tmp_path / "m.yaml"
    save_mission(m, out, library_file=library_path(src, m.library))
    saved = yaml.safe_load(out.read_text())
    assert list(saved["robots"]) == list(source["robots"])
    assert list(saved["markers"]) == list(source["markers"])
    assert saved["barriers"] == source["barriers"]
    for robot, task in source["tasks"].items():
        assert [s["id"] for s in saved["tasks"][robot]] == [s["id"] for s in task]
        assert [s.get("label") for s in saved["tasks"][robot]] == [s.get("label") for s in task]


# -- missions changed by operations -------------------------------------------------------


def _engine() -> tuple[Engine, Library]:
    m, lib = load_mission(REPO / "tests" / "data" / "mars_sample_return_v1.yaml")
    return Engine(m, lib), lib


def test_round_trip_after_engine_operations(tmp_path: Path):
    e, _ = _engine()
    a = e.submit(
        AddSkill(
            robot="lru1",
            skill="drive_to",
            label="géologie: #1 'north'",
            params={"goal": {"x": 3, "y": 4}},
        )
    )
    e.submit(
        EditSkill(
            id=a.value["id"],
            params={"speed": 0.8},
            policies=Policies(retries=2, recharge_below=0.2),
        )
    )
    e.submit(
        MarkerAdd(
            name="POI-C",
            marker=PoseMarker(pose=Pose(x=5.5, y=-6.25, yaw=1.0), description="new spot"),
        )
    )
    b = e.submit(AddSkill(robot="lru2", skill="drive_to", bindings={"goal": "POI-C"}, at=0))
    e.submit(AddBarrier(ids=[a.value["id"], b.value["id"]]))
    e.submit(MoveSkill(id="lru2-6", index=0))
    # part of the mission is on the robots and has run
    sync_and_ack(e, "ardea")
    report = Reporter(e)
    report("ardea", "ardea-1", "running")
    report("ardea", "ardea-1", "success", "airborne\nat 5 m")
    report("ardea", "ardea-2", "running")
    report("ardea", "ardea-2", "failure", "gust: lost position")
    m = e.mission
    assert m.revision > 0 and m.barriers and "POI-C" in m.markers

    out = tmp_path / "ops.yaml"
    loaded, text = round_trip(m, out, LIBRARY)
    assert_same(loaded, m, out, LIBRARY)
    assert validate_file(out) == []
    # saving the loaded mission again gives the same text
    save_mission(loaded, tmp_path / "again.yaml", library_file=LIBRARY)
    assert (tmp_path / "again.yaml").read_text() == text
    # the execution log is in the file
    data = yaml.safe_load(text)
    ardea = {s["id"]: s for s in data["tasks"]["ardea"]}
    assert ardea["ardea-1"]["status"] == "success"
    assert ardea["ardea-2"]["status"] == "failure"
    assert ardea["ardea-3"]["status"] == "idle_synchronized"
    assert data["report_seqs"] == {"ardea": 4}


def test_round_trip_keeps_stale_values_of_queued_skills(tmp_path: Path):
    """A queued skill bound to a marker that moved keeps the value it was sent
    with (the brief: skills already on a robot are not changed silently);
    saving and loading must not refresh it from the marker."""
    e, _ = _engine()
    sync_and_ack(e, "ardea")  # ardea-2 explores ROI-north, now queued on the robot
    old = e.mission.find("ardea-2")[2].params["area"]
    applied = e.submit(
        MarkerMove(
            name="ROI-north", value=[Position(x=0, y=0), Position(x=9, y=0), Position(x=9, y=9)]
        )
    )
    assert applied.value["stale"] == ["ardea-2"]
    m = e.mission
    assert m.find("ardea-2")[2].params["area"] == old
    out = tmp_path / "stale.yaml"
    loaded, _ = round_trip(m, out, LIBRARY)
    assert loaded.find("ardea-2")[2].params["area"] == old, (
        "the queued skill's value was silently refreshed from the marker"
    )
    assert_same(loaded, m, out, LIBRARY)


def test_round_trip_after_deleting_a_marker_the_log_used(tmp_path: Path):
    """Deleting a marker keeps the binding of finished skills (the log keeps
    the name it ran with); the saved file must still load."""
    e, _ = _engine()
    sync_and_ack(e, "ardea")
    report = Reporter(e)
    for sid in ("ardea-1", "ardea-2"):
        report("ardea", sid, "running")
        report("ardea", sid, "success")
    e.submit(MarkerDelete(name="ROI-north"))
    m = e.mission
    out = tmp_path / "deleted.yaml"
    save_mission(m, out, library_file=LIBRARY)
    assert [str(i) for i in validate_file(out)] == []
    loaded, _ = load_mission(out)
    assert_same(loaded, m, out, LIBRARY)
