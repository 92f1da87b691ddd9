"""Requests from several clients: request-id idempotency, optimistic
concurrency (expected_revision), per-client undo/redo, load/new mission."""

from __future__ import annotations

import pytest

from backend.core.model import Mission, Pose, SkillInstance, Status
from backend.core.ops import (
    AddBarrier,
    AddSkill,
    DeleteSkills,
    EditSkill,
    LoadMission,
    MarkerAdd,
    MarkerDelete,
    MarkerMove,
    MarkerRename,
    MoveSkill,
    NewMission,
    Redo,
    RemoveBarrier,
    Report,
    Sync,
    Undo,
    Unsync,
    UnsyncDone,
)
from backend.core.rules.engine import Refusal
from backend.files.missions import load_mission

from .conftest import SAMPLE_RETURN, TUTORIAL, invariant_problems

S = Status
POI_A = {"x": 10.0, "y": 5.0, "z": 0.0, "roll": 0.0, "pitch": 0.0, "yaw": 0.0}


def add(engine, client="c1", robot="lru1", **kw):
    return engine.submit(AddSkill(robot=robot, skill="recharge", **kw), client=client)


def undo(engine, client="c1"):
    return engine.submit(Undo(), client=client)


def redo(engine, client="c1"):
    return engine.submit(Redo(), client=client)


# -- request ids ---------------------------------------------------------------------


class TestRequestIds:
    def test_same_client_and_request_id_applied_once(self, engine, ids, snapshot):
        first = engine.submit(
            AddSkill(robot="lru1", skill="recharge"), client="c1", request_id="r-1"
        )
        before = snapshot(engine)
        again = engine.submit(
            AddSkill(robot="lru1", skill="recharge"), client="c1", request_id="r-1"
        )
        assert again.duplicate and not first.duplicate
        assert again.value["id"] == first.value["id"]
        assert again.revision == first.revision
        assert snapshot(engine) == before
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2", first.value["id"]]

    def test_other_client_with_the_same_request_id_is_applied(self, engine, ids):
        a = engine.submit(AddSkill(robot="lru1", skill="recharge"), client="c1", request_id="r-1")
        b = engine.submit(AddSkill(robot="lru1", skill="recharge"), client="c2", request_id="r-1")
        assert not b.duplicate
        assert a.value["id"] != b.value["id"]
        assert ids(engine, "lru1")[-2:] == [a.value["id"], b.value["id"]]

    def test_new_request_id_is_a_new_request(self, engine, ids):
        engine.submit(AddSkill(robot="lru1", skill="recharge"), client="c1", request_id="r-1")
        engine.submit(AddSkill(robot="lru1", skill="recharge"), client="c1", request_id="r-2")
        assert len(ids(engine, "lru1")) == 4

    def test_a_refused_request_can_be_retried(self, engine, sync, refused, ids):
        sync(engine, "lru1", through="lru1-1")
        op = DeleteSkills(ids=["lru1-1"])
        refused(
            engine, lambda: engine.submit(op, client="c1", request_id="r-9"), "not_idle", "lru1-1"
        )
        engine.submit(UnsyncDone(robot="lru1", ids=engine.plan_unsync(Unsync(robot="lru1"))))
        engine.release("lru1")
        applied = engine.submit(op, client="c1", request_id="r-9")
        assert not applied.duplicate
        assert ids(engine, "lru1") == ["lru1-2"]

    def test_a_retried_edit_with_a_revision_is_not_refused_as_stale(self, engine, skill):
        seen = engine.mission.revision
        op = EditSkill(id="lru1-1", label="x")
        engine.submit(op, client="c1", request_id="r-1", expected_revision=seen)
        again = engine.submit(op, client="c1", request_id="r-1", expected_revision=seen)
        assert again.duplicate
        assert skill(engine, "lru1-1").label == "x"


# -- optimistic concurrency ------------------------------------------------------------


class TestExpectedRevision:
    def test_stale_edit_refused(self, engine, refused, skill):
        seen = engine.mission.revision
        engine.submit(EditSkill(id="lru1-1", params={"speed": 0.8}), client="c2")
        r = refused(
            engine,
            lambda: engine.submit(
                EditSkill(id="lru1-1", label="x"), client="c1", expected_revision=seen
            ),
            "stale",
            "lru1-1",
            str(seen),
        )
        assert str(engine.mission.revision) in r.message
        assert skill(engine, "lru1-1").label == "drive to POI-A"

    def test_edit_accepted_when_another_skill_changed(self, engine, skill):
        seen = engine.mission.revision
        engine.submit(EditSkill(id="lru1-1", params={"speed": 0.8}), client="c2")
        engine.submit(EditSkill(id="lru1-2", label="other"), client="c2")
        engine.submit(EditSkill(id="lru2-1", label="mine"), client="c1", expected_revision=seen)
        engine.submit(
            EditSkill(id="lru1-2", label="mine too"),
            client="c1",
            expected_revision=engine.mission.revision,
        )
        assert skill(engine, "lru2-1").label == "mine"
        assert skill(engine, "lru1-1").params["speed"] == 0.8

    def test_current_revision_accepted(self, engine, skill):
        engine.submit(EditSkill(id="lru1-1", label="a"), client="c2")
        engine.submit(
            EditSkill(id="lru1-1", label="b"),
            client="c1",
            expected_revision=engine.mission.revision,
        )
        assert skill(engine, "lru1-1").label == "b"

    def test_two_clients_editing_the_same_skill(self, engine, refused, skill):
        seen = engine.mission.revision  # both consoles show this revision
        engine.submit(
            EditSkill(id="lru2-1", params={"speed": 0.8}), client="c1", expected_revision=seen
        )
        refused(
            engine,
            lambda: engine.submit(
                EditSkill(id="lru2-1", params={"speed": 0.3}), client="c2", expected_revision=seen
            ),
            "stale",
            "lru2-1",
        )
        assert skill(engine, "lru2-1").params["speed"] == 0.8, "the first edit is not lost"
        # c2 reloads and tries again knowingly
        engine.submit(
            EditSkill(id="lru2-1", params={"speed": 0.3}),
            client="c2",
            expected_revision=engine.mission.revision,
        )
        assert skill(engine, "lru2-1").params["speed"] == 0.3

    def test_stale_delete_refused(self, engine, refused):
        seen = engine.mission.revision
        engine.submit(EditSkill(id="lru1-2", label="changed"), client="c2")
        refused(
            engine,
            lambda: engine.submit(DeleteSkills(ids=["lru1-2"]), expected_revision=seen),
            "stale",
            "lru1-2",
        )

    def test_stale_move_refused_when_the_list_changed(self, engine, refused, ids):
        seen = engine.mission.revision
        add(engine, client="c2", at=0)
        refused(
            engine,
            lambda: engine.submit(MoveSkill(id="lru1-2", index=0), expected_revision=seen),
            "stale",
            "lru1",
        )
        # the other robot's list did not change
        engine.submit(MoveSkill(id="lru2-2", index=0), expected_revision=seen)
        assert ids(engine, "lru2") == ["lru2-2", "lru2-1"]

    def test_stale_add_at_a_position_refused_when_the_list_changed(self, engine, refused):
        seen = engine.mission.revision
        engine.submit(MoveSkill(id="lru1-2", index=0), client="c2")
        refused(
            engine,
            lambda: engine.submit(
                AddSkill(robot="lru1", skill="recharge", at=1), expected_revision=seen
            ),
            "stale",
            "lru1",
        )
        engine.submit(AddSkill(robot="lru2", skill="recharge", at=1), expected_revision=seen)

    def test_stale_marker_move_refused(self, engine, refused):
        seen = engine.mission.revision
        engine.submit(MarkerMove(name="POI-A", value=Pose(x=1.0)), client="c2")
        refused(
            engine,
            lambda: engine.submit(
                MarkerMove(name="POI-A", value=Pose(x=2.0)), expected_revision=seen
            ),
            "stale",
            "POI-A",
        )
        assert engine.mission.markers["POI-A"].pose == Pose(x=1.0)

    def test_stale_barrier_refused(self, engine, refused):
        seen = engine.mission.revision
        engine.submit(EditSkill(id="lru2-1", label="changed"), client="c2")
        refused(
            engine,
            lambda: engine.submit(AddBarrier(ids=["lru1-1", "lru2-1"]), expected_revision=seen),
            "stale",
            "lru2-1",
        )

    def test_edit_with_a_revision_from_before_a_load_is_stale(self, engine, refused):
        """After the mission was replaced, an edit made against the old
        mission must not be applied silently to the new one."""
        seen = engine.mission.revision
        mission, _ = load_mission(TUTORIAL)
        engine.submit(LoadMission(mission=mission), client="c2")
        refused(
            engine,
            lambda: engine.submit(
                EditSkill(id="lru1-1", label="meant for the old mission"), expected_revision=seen
            ),
            "stale",
        )


# -- undo / redo -------------------------------------------------------------------------


class TestUndo:
    def test_nothing_to_undo_or_redo(self, engine, refused):
        refused(engine, lambda: undo(engine), "nothing_to_undo")
        refused(engine, lambda: redo(engine), "nothing_to_redo")

    def test_undo_add(self, engine, ids):
        sid = add(engine).value["id"]
        rev = engine.mission.revision
        applied = undo(engine)
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2"]
        assert sid not in engine.mission.all_ids()
        assert applied.revision == rev + 1, "undo is a new revision"
        assert applied.value["undone"] == "add"

    def test_undo_delete_restores_position_content_and_barrier(self, engine, skill, ids):
        bid = engine.submit(AddBarrier(ids=["lru1-1", "lru2-1"]), client="c1").value["barrier"]
        before = skill(engine, "lru1-1").model_dump()
        engine.submit(DeleteSkills(ids=["lru1-1", "lru2-2"]), client="c1")
        assert bid not in engine.mission.barriers
        undo(engine)
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2"]
        assert ids(engine, "lru2") == ["lru2-1", "lru2-2"]
        after = skill(engine, "lru1-1").model_dump()
        assert {k: v for k, v in after.items() if k != "rev"} == {
            k: v for k, v in before.items() if k != "rev"
        }
        assert engine.mission.barriers[bid].skills == ["lru1-1", "lru2-1"]

    def test_undo_delete_gives_the_bound_parameter_the_current_marker_value(self, engine, skill):
        engine.submit(DeleteSkills(ids=["lru1-2"]), client="c1")
        engine.submit(MarkerMove(name="POI-A", value=Pose(x=3.0, y=4.0)), client="c2")
        undo(engine)
        s = skill(engine, "lru1-2")
        if s.bindings.get("target") == "POI-A":
            assert s.params["target"] == {
                "x": 3.0,
                "y": 4.0,
                "z": 0.0,
                "roll": 0.0,
                "pitch": 0.0,
                "yaw": 0.0,
            }

    @pytest.mark.parametrize("change", ["rename", "delete"])
    def test_undo_delete_does_not_bind_to_a_marker_that_is_gone(self, engine, skill, change):
        engine.submit(DeleteSkills(ids=["lru1-2"]), client="c1")
        if change == "rename":
            engine.submit(MarkerRename(name="POI-A", new_name="POI-North"), client="c2")
        else:
            engine.submit(MarkerDelete(name="POI-A"), client="c2")
        try:
            undo(engine)
        except Refusal:
            return  # refusing is acceptable
        for name in skill(engine, "lru1-2").bindings.values():
            assert name in engine.mission.markers, f"bound to missing marker {name}"

    def test_undo_does_not_overwrite_another_clients_later_edit(self, engine, skill):
        """c1 renames a skill, c2 then changes its speed, c1 undoes: c2's
        change must survive (or the undo be refused), not be lost silently."""
        engine.submit(EditSkill(id="lru2-1", label="x"), client="c1")
        engine.submit(EditSkill(id="lru2-1", params={"speed": 0.9}), client="c2")
        try:
            undo(engine, "c1")
        except Refusal:
            pass
        assert skill(engine, "lru2-1").params["speed"] == 0.9

    def test_undo_move(self, engine, ids):
        engine.submit(MoveSkill(id="lru1-2", index=0), client="c1")
        undo(engine)
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2"]

    def test_undo_edit(self, engine, skill):
        before = skill(engine, "lru1-1")
        engine.submit(
            EditSkill(id="lru1-1", label="x", params={"speed": 0.9, "goal": {"x": 1.0}}),
            client="c1",
        )
        undo(engine)
        after = skill(engine, "lru1-1")
        assert (after.label, after.params, after.bindings) == (
            before.label,
            before.params,
            before.bindings,
        )

    def test_undo_barrier_and_unbarrier(self, engine):
        bid = engine.submit(AddBarrier(ids=["lru1-1", "lru2-1"]), client="c1").value["barrier"]
        undo(engine)
        assert engine.mission.barriers == {}
        bid = engine.submit(AddBarrier(ids=["lru1-1", "lru2-1"]), client="c1").value["barrier"]
        engine.submit(RemoveBarrier(barrier=bid), client="c1")
        undo(engine)
        assert engine.mission.barriers[bid].skills == ["lru1-1", "lru2-1"]

    def test_redo_of_a_barrier_brings_back_the_same_barrier(self, engine):
        """Add then remove a barrier, undo both, redo both: the redone
        removal must find the barrier the redone add created."""
        bid = engine.submit(AddBarrier(ids=["lru1-1", "lru2-1"]), client="c1").value["barrier"]
        engine.submit(RemoveBarrier(barrier=bid), client="c1")
        undo(engine)
        undo(engine)
        assert engine.mission.barriers == {}
        redo(engine)
        assert engine.mission.barriers.get(bid) is not None
        assert engine.mission.barriers[bid].skills == ["lru1-1", "lru2-1"]
        redo(engine)
        assert engine.mission.barriers == {}

    def test_undo_marker_add_move_rename(self, engine, skill):
        engine.submit(
            MarkerAdd(name="POI-B", marker={"kind": "pose", "pose": {"x": 1.0}}), client="c1"
        )
        undo(engine)
        assert "POI-B" not in engine.mission.markers
        engine.submit(MarkerMove(name="POI-A", value=Pose(x=3.0)), client="c1")
        assert skill(engine, "lru1-1").params["goal"]["x"] == 3.0
        undo(engine)
        assert engine.mission.markers["POI-A"].pose == Pose(x=10.0, y=5.0)
        assert skill(engine, "lru1-1").params["goal"] == POI_A
        engine.submit(MarkerRename(name="POI-A", new_name="POI-C"), client="c1")
        undo(engine)
        assert "POI-A" in engine.mission.markers and "POI-C" not in engine.mission.markers
        assert skill(engine, "lru1-1").bindings == {"goal": "POI-A"}

    def test_undo_marker_delete(self, engine, skill):
        engine.submit(MarkerDelete(name="POI-A"), client="c1")
        applied = undo(engine)
        assert applied.value.get("undone") == "marker_delete"
        assert engine.mission.markers["POI-A"].pose == Pose(x=10.0, y=5.0)
        assert skill(engine, "lru1-1").bindings == {"goal": "POI-A"}
        assert skill(engine, "lru1-2").bindings == {"target": "POI-A"}

    def test_undo_after_the_skill_was_synchronized_refused(self, engine, sync, refused, ids):
        sid = add(engine).value["id"]
        sync(engine, "lru1")
        r = refused(engine, lambda: undo(engine), "not_idle", "undo", sid, "lru1", skill=sid)
        assert "unsynchronize" in r.message
        assert sid in ids(engine, "lru1")

    def test_undo_edit_after_the_skill_was_synchronized_refused(self, engine, sync, refused, skill):
        engine.submit(EditSkill(id="lru1-1", label="x"), client="c1")
        sync(engine, "lru1", through="lru1-1")
        refused(engine, lambda: undo(engine), "not_idle", "undo", "lru1-1")
        assert skill(engine, "lru1-1").label == "x"

    def test_redo(self, engine, skill):
        engine.submit(EditSkill(id="lru1-1", label="x"), client="c1")
        undo(engine)
        assert skill(engine, "lru1-1").label == "drive to POI-A"
        applied = redo(engine)
        assert applied.value["redone"] == "edit"
        assert skill(engine, "lru1-1").label == "x"
        undo(engine)  # a redone edit can be undone again
        assert skill(engine, "lru1-1").label == "drive to POI-A"

    def test_redo_of_an_add_brings_back_the_same_skill(self, engine, skill, ids):
        """Undo add + edit, then redo both: the skill comes back with its id,
        so the redo of the edit (and any client holding the id) finds it."""
        sid = add(engine).value["id"]
        engine.submit(EditSkill(id=sid, params={"target_level": 0.5}), client="c1")
        undo(engine)
        undo(engine)
        assert sid not in engine.mission.all_ids()
        redo(engine)
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2", sid]
        redo(engine)
        assert skill(engine, sid).params["target_level"] == 0.5

    def test_a_new_edit_clears_redo(self, engine, refused):
        engine.submit(EditSkill(id="lru1-1", label="x"), client="c1")
        undo(engine)
        engine.submit(EditSkill(id="lru1-2", label="y"), client="c1")
        refused(engine, lambda: redo(engine), "nothing_to_redo")

    def test_undo_stacks_are_per_client(self, engine, refused, skill, ids):
        sid = add(engine, client="c1").value["id"]
        refused(engine, lambda: undo(engine, "c2"), "nothing_to_undo")
        engine.submit(EditSkill(id="lru2-1", label="by c2"), client="c2")
        undo(engine, "c1")
        assert sid not in ids(engine, "lru1")
        assert skill(engine, "lru2-1").label == "by c2", "c1's undo leaves c2's edit alone"
        undo(engine, "c2")
        assert skill(engine, "lru2-1").label == "drive next to POI-A"
        # redo is per client too
        refused(engine, lambda: redo(engine, "c3"), "nothing_to_redo")
        redo(engine, "c1")
        assert len(ids(engine, "lru1")) == 3

    def test_another_clients_edit_does_not_clear_my_redo(self, engine, skill):
        engine.submit(EditSkill(id="lru1-1", label="x"), client="c1")
        undo(engine, "c1")
        engine.submit(EditSkill(id="lru2-1", label="y"), client="c2")
        redo(engine, "c1")
        assert skill(engine, "lru1-1").label == "x"

    def test_robot_operations_are_not_undone(self, engine, sync, refused, status_of):
        sync(engine, "lru1")
        refused(engine, lambda: undo(engine), "nothing_to_undo")
        assert status_of(engine, "lru1-1") == S.IDLE_SYNCHRONIZED

    def test_undo_delete_after_another_client_deleted_the_barrier_partner(self, engine, refused):
        """c1 deletes a barrier member (the barrier dissolves), c2 deletes the
        partner, c1 undoes: the restored skill must not come back in a barrier
        with a skill that no longer exists."""
        engine.submit(AddBarrier(ids=["lru1-1", "lru2-1"]), client="c1")
        engine.submit(DeleteSkills(ids=["lru1-1"]), client="c1")
        engine.submit(DeleteSkills(ids=["lru2-1"]), client="c2")
        try:
            undo(engine, "c1")
        except Exception:  # refusing is acceptable, as long as nothing broke
            pass
        assert invariant_problems(engine) == []

    def test_undo_delete_after_the_partner_joined_another_barrier(self, engine3):
        a = engine3.ardea_first
        engine3.submit(AddBarrier(ids=["lru1-1", "lru2-1"]), client="c1")
        engine3.submit(DeleteSkills(ids=["lru1-1"]), client="c1")
        engine3.submit(AddBarrier(ids=["lru2-1", a]), client="c2")
        try:
            undo(engine3, "c1")
        except Exception:
            pass
        assert invariant_problems(engine3) == []


# -- load / new --------------------------------------------------------------------------


def other_mission() -> Mission:
    mission, _ = load_mission(SAMPLE_RETURN)
    return mission


class TestLoadNew:
    def test_load_replaces_the_mission(self, engine, ids):
        add(engine)
        rev = engine.mission.revision
        new = other_mission()
        applied = engine.submit(LoadMission(mission=new), client="c1")
        assert applied.revision == rev + 1 == engine.mission.revision
        assert engine.mission.name == new.name
        assert set(engine.mission.robots) == set(new.robots)
        assert ids(engine, "lru1") == [s.id for s in new.tasks["lru1"]]
        assert engine.mission.markers.keys() == new.markers.keys()
        assert engine.mission.barriers == new.barriers
        add(engine)
        assert engine.mission.revision == rev + 2

    def test_new_empties_the_plan(self, engine, sync, report):
        engine.submit(AddBarrier(ids=["lru1-1", "lru2-1"]))
        rev = engine.mission.revision
        engine.submit(NewMission(name="Day 2"))
        m = engine.mission
        assert m.revision == rev + 1
        assert m.name == "Day 2"
        assert set(m.robots) == {"lru1", "lru2"}
        assert all(task == [] for task in m.tasks.values())
        assert m.barriers == {} and m.markers == {}

    @pytest.mark.parametrize("status", [S.IDLE_SYNCHRONIZED, S.SYNCHWAITING, S.RUNNING, S.PAUSED])
    @pytest.mark.parametrize("op", ["load", "new"])
    def test_refused_while_robots_hold_synchronized_skills(
        self, engine, bring, refused, status, op
    ):
        bring(engine, "lru2", "lru2-1", status)
        what = LoadMission(mission=other_mission()) if op == "load" else NewMission()
        r = refused(engine, lambda: engine.submit(what), "robots_busy", "lru2")
        assert "lru1" not in r.message

    def test_allowed_when_robots_hold_only_finished_skills(self, engine, bring):
        bring(engine, "lru1", "lru1-1", S.SUCCESS)
        bring(engine, "lru2", "lru2-1", S.FAILURE)
        engine.submit(NewMission())
        assert engine.mission.tasks["lru1"] == []

    def test_refused_while_a_sync_is_in_flight(self, engine, refused):
        """A robot answering a command sent for the old mission must not
        change the new one: replacing the mission waits for it."""
        engine.plan_sync(Sync(robot="lru1"))
        mission, _ = load_mission(TUTORIAL)
        before = engine.mission.model_dump(mode="json")
        with pytest.raises(Refusal) as info:
            engine.submit(LoadMission(mission=mission))
        assert info.value.code in ("robots_busy", "robot_busy")
        assert "lru1" in info.value.message
        assert engine.mission.model_dump(mode="json") == before

    def test_ids_are_not_reused_after_a_load(self, engine):
        handed_out = {add(engine).value["id"], add(engine, robot="lru2").value["id"]}
        mission, _ = load_mission(TUTORIAL)
        engine.submit(LoadMission(mission=mission))
        later = {add(engine).value["id"], add(engine, robot="lru2").value["id"]}
        assert not handed_out & later

    def test_report_sequence_survives_a_load(self, engine, sync, report, status_of):
        sync(engine, "lru1", through="lru1-1")
        report(engine, "lru1", "lru1-1", S.RUNNING)
        report(engine, "lru1", "lru1-1", S.SUCCESS)
        mission, _ = load_mission(TUTORIAL)
        engine.submit(LoadMission(mission=mission))
        sync(engine, "lru1")
        late = engine.submit(Report(robot="lru1", seq=1, id="lru1-1", status=S.RUNNING))
        assert late.duplicate
        assert status_of(engine, "lru1-1") == S.IDLE_SYNCHRONIZED

    def test_load_clears_undo(self, engine, refused):
        add(engine)
        engine.submit(NewMission(), client="c2")
        refused(engine, lambda: undo(engine), "nothing_to_undo")

    def test_a_load_that_was_not_applied_keeps_undo(self, engine):
        add(engine)

        class Full:  # what the server's journal recorder does on a full disk
            def record(self, batch, origin):
                raise Refusal("journal_failed", "disk full: the mission was not changed")

        engine.recorder = Full()
        with pytest.raises(Refusal):
            engine.submit(NewMission(), client="c2")
        engine.recorder = None
        assert undo(engine).value["undone"] == "add"

    def test_invalid_mission_refused(self, engine, refused):
        bad = Mission(
            library="libraries/mars.yaml",
            robots={"lru1": {"type": "lru_science"}},
            tasks={"lru1": [SkillInstance(id="x-1", skill="pick_stone")]},
        )
        refused(
            engine, lambda: engine.submit(LoadMission(mission=bad)), "bad_mission", "pick_stone"
        )

    def test_invalid_mission_with_broken_section_order_refused(self, engine, refused):
        bad, _ = load_mission(TUTORIAL)
        bad.tasks["lru1"][0].status = S.IDLE
        bad.tasks["lru1"][1].status = S.IDLE_SYNCHRONIZED
        refused(engine, lambda: engine.submit(LoadMission(mission=bad)), "bad_mission")
