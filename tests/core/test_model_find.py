"""`Mission.find` remembers where it saw each skill; what it remembers is a
hint, so whatever changes the task lists (events, the rules, a test) never
makes it answer wrong, and it never makes two equal missions differ."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from backend.core.model import Mission, RobotSpec, SkillInstance


def scan(m: Mission, skill_id: str) -> tuple[str, int, SkillInstance] | None:
    for robot, task in m.tasks.items():
        for i, s in enumerate(task):
            if s.id == skill_id:
                return robot, i, s
    return None


def mission(per_robot: int = 4) -> Mission:
    m = Mission(library="lib.yaml")
    for r in ("a", "b", "c"):
        m.robots[r] = RobotSpec(type="t")
        m.tasks[r] = [
            SkillInstance(id=f"{r}-{j}", skill="drive_to") for j in range(1, per_robot + 1)
        ]
    return m


edits = st.lists(
    st.tuples(
        st.sampled_from(["find", "insert", "delete", "move", "replace", "swap_lists"]),
        st.sampled_from(["a", "b", "c"]),
        st.integers(0, 9),
        st.integers(0, 9),
    ),
    max_size=60,
)


@settings(max_examples=300, deadline=None)
@given(edits)
def test_find_answers_as_a_full_scan_whatever_changed_the_lists(steps):
    m = mission()
    fresh = iter(range(100, 10_000))
    ids = [s.id for t in m.tasks.values() for s in t] + ["a-99", "nope"]
    for what, robot, x, y in steps:
        task = m.tasks[robot]
        if what == "insert":
            sid = f"{robot}-{next(fresh)}"
            task.insert(min(x, len(task)), SkillInstance(id=sid, skill="drive_to"))
            ids.append(sid)
        elif what == "delete" and task:
            del task[x % len(task)]
        elif what == "move" and task:
            task.insert(y % len(task), task.pop(x % len(task)))
        elif what == "replace" and task:
            i = x % len(task)
            task[i] = task[i].model_copy(update={"label": f"edited {y}"})
        elif what == "swap_lists":  # a whole list replaced by another object
            m.tasks[robot] = list(task)
        for sid in ids:  # every step: warm hints, stale hints and unknown ids
            assert m.find(sid) == scan(m, sid), sid


def test_a_deleted_skill_is_not_found_and_not_remembered():
    m = mission()
    assert m.find("b-3") == ("b", 2, m.tasks["b"][2])
    del m.tasks["b"][2]
    assert m.find("b-3") is None
    assert "b-3" not in m._hints  # a long mission does not keep every deleted id
    assert m.find("b-4") == ("b", 2, m.tasks["b"][2])


def test_hints_change_neither_equality_nor_what_is_stored():
    looked_up, untouched = mission(), mission()
    for sid in ("a-1", "b-2", "c-4"):
        looked_up.find(sid)
    assert looked_up == untouched
    assert looked_up.model_dump_json() == untouched.model_dump_json()
    copy = looked_up.model_copy(deep=True)
    copy.tasks["a"].pop(0)
    assert copy != untouched  # content still decides
    assert copy.find("a-2") == ("a", 0, copy.tasks["a"][0])
    assert looked_up.find("a-1") == (
        "a",
        0,
        looked_up.tasks["a"][0],
    )  # the original's lists are its own


def test_a_fresh_mission_notes_every_list_on_its_first_lookup():
    m = mission()
    assert m.find("c-2") == ("c", 1, m.tasks["c"][1])
    # the other robots' skills are noted too: their first lookups need no scan
    assert {sid for sid in m._hints} == {s.id for t in m.tasks.values() for s in t}


def test_an_added_skill_is_noted_where_it_was_put():
    from backend.core.events import EventBatch, SkillAdded, apply_events

    m = mission()
    m.find("a-1")  # every list noted
    added = SkillInstance(id="b-9", skill="drive_to")
    m = apply_events(
        m, EventBatch(revision=1, events=[SkillAdded(robot="b", index=4, skill=added)])
    )
    assert m._hints["b-9"] == ("b", 4)
    assert m.find("b-9") == ("b", 4, m.tasks["b"][4])


def test_a_skill_a_few_places_off_its_hint_is_found_without_a_scan(monkeypatch):
    m = mission(per_robot=50)
    m.find("a-1")  # every list noted
    del m.tasks["a"][0]  # every hint of robot a is one place off now
    m.tasks["a"].insert(10, SkillInstance(id="a-77", skill="drive_to"))
    scans = []
    monkeypatch.setattr(Mission, "_rehint", lambda self, *a: scans.append(a))
    for j in (2, 11, 30, 50):
        sid = f"a-{j}"
        assert m.find(sid) == scan(m, sid)
        assert m._hints[sid] == ("a", scan(m, sid)[1])  # noted where it is now
    assert scans == []
