"""Barriers (skills of several robots started together) and markers (named
poses, positions and areas that parameters can be bound to)."""

from __future__ import annotations

import pytest

from backend.core.checks import check_mission
from backend.core.model import Pose, Position, Status
from backend.core.ops import (
    AddBarrier,
    AddSkill,
    EditSkill,
    MarkerAdd,
    MarkerDelete,
    MarkerMove,
    MarkerRename,
    RemoveBarrier,
    Sync,
    SyncAck,
    Unsync,
    UnsyncDone,
)

S = Status
POI_A = {"x": 10.0, "y": 5.0, "z": 0.0, "roll": 0.0, "pitch": 0.0, "yaw": 0.0}
NEW_POSE = Pose(x=20.0, y=-3.0, yaw=1.5)
NEW_POSE_D = {"x": 20.0, "y": -3.0, "z": 0.0, "roll": 0.0, "pitch": 0.0, "yaw": 1.5}
AREA = [{"x": 0.0, "y": 0.0}, {"x": 4.0, "y": 0.0}, {"x": 4.0, "y": 4.0}]


def barrier(engine, *ids):
    return engine.submit(AddBarrier(ids=list(ids))).value["barrier"]


# -- barriers -------------------------------------------------------------------------


class TestBarrierAdd:
    def test_joins_one_idle_skill_per_robot(self, engine):
        rev = engine.mission.revision
        applied = engine.submit(AddBarrier(ids=["lru1-2", "lru2-2"]))
        bid = applied.value["barrier"]
        assert engine.mission.barriers[bid].skills == ["lru1-2", "lru2-2"]
        assert engine.mission.barrier_of("lru1-2") == engine.mission.barrier_of("lru2-2") == bid
        assert applied.revision == rev + 1
        assert engine.barrier_partners("lru1-2") == [("lru2", "lru2-2")]

    def test_three_robots(self, engine3):
        a = engine3.ardea_first
        bid = barrier(engine3, "lru1-1", "lru2-1", a)
        assert engine3.mission.barriers[bid].skills == ["lru1-1", "lru2-1", a]
        assert sorted(engine3.barrier_partners(a)) == [("lru1", "lru1-1"), ("lru2", "lru2-1")]

    def test_barrier_ids_are_not_reused(self, engine):
        b1 = barrier(engine, "lru1-1", "lru2-1")
        engine.submit(RemoveBarrier(barrier=b1))
        b2 = barrier(engine, "lru1-1", "lru2-1")
        assert b1 != b2

    def test_two_skills_of_one_robot_refused(self, engine, refused):
        refused(
            engine,
            lambda: engine.submit(AddBarrier(ids=["lru1-1", "lru1-2"])),
            "barrier_invalid",
            "lru1-1",
            "lru1-2",
            "lru1",
            robot="lru1",
        )

    def test_two_skills_of_one_robot_among_others_refused(self, engine3, refused):
        refused(
            engine3,
            lambda: engine3.submit(AddBarrier(ids=["lru1-1", engine3.ardea_first, "lru1-2"])),
            "barrier_invalid",
            "lru1",
        )

    def test_the_same_skill_twice_refused(self, engine, refused):
        # the operation model accepts a repeated id; the engine must not
        refused(
            engine,
            lambda: engine.submit(AddBarrier(ids=["lru1-1", "lru1-1"])),
            "barrier_invalid",
            "lru1-1",
        )

    @pytest.mark.parametrize("status", [S.IDLE_SYNCHRONIZED, S.RUNNING, S.SUCCESS, S.FAILURE])
    def test_non_idle_skill_refused(self, engine, bring, refused, status):
        bring(engine, "lru1", "lru1-1", status)
        refused(
            engine,
            lambda: engine.submit(AddBarrier(ids=["lru2-1", "lru1-1"])),
            "not_idle",
            "lru1-1",
            "lru1",
            status.value,
            robot="lru1",
            skill="lru1-1",
        )

    def test_skill_being_synchronized_refused(self, engine, refused):
        engine.plan_sync(Sync(robot="lru2", through="lru2-1"))
        refused(
            engine,
            lambda: engine.submit(AddBarrier(ids=["lru1-1", "lru2-1"])),
            "locked",
            "lru2-1",
            skill="lru2-1",
        )

    def test_skill_already_in_a_barrier_refused(self, engine3, refused):
        bid = barrier(engine3, "lru1-1", "lru2-1")
        refused(
            engine3,
            lambda: engine3.submit(AddBarrier(ids=[engine3.ardea_first, "lru2-1"])),
            "barrier_invalid",
            "lru2-1",
            bid,
            skill="lru2-1",
        )

    def test_unknown_skill_refused(self, engine, refused):
        refused(
            engine,
            lambda: engine.submit(AddBarrier(ids=["lru1-1", "nope-9"])),
            "unknown_skill",
            "nope-9",
        )

    def test_barrier_skills_can_be_synchronized_one_robot_at_a_time(self, engine, sync, status_of):
        barrier(engine, "lru1-1", "lru2-1")
        sync(engine, "lru1", through="lru1-1")
        assert status_of(engine, "lru1-1") == S.IDLE_SYNCHRONIZED
        assert status_of(engine, "lru2-1") == S.IDLE

    def test_barrier_members_wait_then_start(self, engine, sync, report, status_of):
        barrier(engine, "lru1-1", "lru2-1")
        sync(engine, "lru1", through="lru1-1")
        sync(engine, "lru2", through="lru2-1")
        report(engine, "lru1", "lru1-1", S.SYNCHWAITING)
        report(engine, "lru2", "lru2-1", S.SYNCHWAITING)
        report(engine, "lru1", "lru1-1", S.RUNNING)
        report(engine, "lru2", "lru2-1", S.RUNNING)
        assert status_of(engine, "lru1-1") == status_of(engine, "lru2-1") == S.RUNNING


class TestBarrierRemove:
    def test_removes_an_idle_barrier(self, engine):
        bid = barrier(engine, "lru1-1", "lru2-1")
        rev = engine.mission.revision
        engine.submit(RemoveBarrier(barrier=bid))
        assert bid not in engine.mission.barriers
        assert engine.mission.barrier_of("lru1-1") is None
        assert engine.mission.revision == rev + 1

    def test_unknown_barrier_refused(self, engine, refused):
        refused(
            engine, lambda: engine.submit(RemoveBarrier(barrier="b77")), "unknown_barrier", "b77"
        )

    @pytest.mark.parametrize("status", [S.IDLE_SYNCHRONIZED, S.SYNCHWAITING, S.RUNNING])
    def test_non_idle_member_refused(self, engine, bring, refused, status):
        bid = barrier(engine, "lru1-1", "lru2-1")
        bring(engine, "lru2", "lru2-1", status)
        refused(
            engine,
            lambda: engine.submit(RemoveBarrier(barrier=bid)),
            "not_idle",
            bid,
            "lru2-1",
            "lru2",
            robot="lru2",
            skill="lru2-1",
        )
        assert engine.mission.barriers[bid].skills == ["lru1-1", "lru2-1"]

    def test_barrier_whose_member_finished_can_be_removed(self, engine, sync, report):
        """A member that failed while waiting can never be unsynchronized: the
        barrier must still be removable so its idle partner is not pinned."""
        bid = barrier(engine, "lru1-1", "lru2-1")
        sync(engine, "lru2", through="lru2-1")
        report(engine, "lru2", "lru2-1", S.SYNCHWAITING)
        report(engine, "lru2", "lru2-1", S.FAILURE)
        engine.submit(RemoveBarrier(barrier=bid))
        assert bid not in engine.mission.barriers


# -- markers ------------------------------------------------------------------------------


class TestMarkerAdd:
    def test_adds_a_marker(self, engine):
        rev = engine.mission.revision
        engine.submit(MarkerAdd(name="ROI-1", marker={"kind": "area", "area": AREA}))
        assert engine.mission.markers["ROI-1"].kind == "area"
        assert engine.mission.revision == rev + 1

    def test_existing_name_refused(self, engine, refused):
        refused(
            engine,
            lambda: engine.submit(
                MarkerAdd(name="POI-A", marker={"kind": "position", "position": {"x": 1.0}})
            ),
            "exists",
            "POI-A",
        )


class TestMarkerMove:
    def test_updates_every_idle_bound_skill(self, engine, skill):
        rev = engine.mission.revision
        applied = engine.submit(MarkerMove(name="POI-A", value=NEW_POSE))
        assert applied.revision == rev + 1
        assert engine.mission.markers["POI-A"].pose == NEW_POSE
        assert skill(engine, "lru1-1").params["goal"] == NEW_POSE_D
        assert skill(engine, "lru1-2").params["target"] == NEW_POSE_D
        assert skill(engine, "lru1-1").bindings == {"goal": "POI-A"}
        # an unbound parameter with the same value does not follow
        assert skill(engine, "lru2-2").params["target"] == {"x": 10.0, "y": 5.0, "z": 0.0}
        assert applied.value["stale"] == []
        assert applied.notes == []

    def test_position_parameter_bound_to_a_pose_marker_follows(self, engine, skill):
        engine.submit(EditSkill(id="lru2-2", bindings={"target": "POI-A"}))
        engine.submit(MarkerMove(name="POI-A", value=NEW_POSE))
        assert skill(engine, "lru2-2").params["target"] == {"x": 20.0, "y": -3.0, "z": 0.0}

    def test_area_and_position_markers(self, engine, skill):
        engine.submit(MarkerAdd(name="ROI-1", marker={"kind": "area", "area": AREA}))
        engine.submit(
            MarkerAdd(name="SPOT", marker={"kind": "position", "position": {"x": 1.0, "y": 1.0}})
        )
        a = engine.submit(
            AddSkill(robot="lru1", skill="explore", bindings={"area": "ROI-1"})
        ).value["id"]
        engine.submit(EditSkill(id="lru2-2", bindings={"target": "SPOT"}))
        moved = [Position(x=0, y=0), Position(x=9, y=0), Position(x=9, y=9), Position(x=0, y=9)]
        engine.submit(MarkerMove(name="ROI-1", value=moved))
        engine.submit(MarkerMove(name="SPOT", value=Position(x=2.0, y=3.0, z=0.5)))
        assert skill(engine, a).params["area"] == [p.model_dump() for p in moved]
        assert skill(engine, "lru2-2").params["target"] == {"x": 2.0, "y": 3.0, "z": 0.5}

    @pytest.mark.parametrize("status", [S.IDLE_SYNCHRONIZED, S.SYNCHWAITING, S.RUNNING, S.PAUSED])
    def test_synchronized_skills_keep_the_old_value_and_are_reported(
        self, engine, bring, skill, status
    ):
        bring(engine, "lru1", "lru1-1", status)
        applied = engine.submit(MarkerMove(name="POI-A", value=NEW_POSE))
        assert skill(engine, "lru1-1").params["goal"] == POI_A, "not changed silently on the robot"
        assert skill(engine, "lru1-2").params["target"] == NEW_POSE_D
        assert applied.value["stale"] == ["lru1-1"]
        assert len(applied.notes) == 1
        note = applied.notes[0]
        for word in ("lru1", "lru1-1", "POI-A", "goal"):
            assert word in note, note

    def test_stale_skill_gets_the_new_value_once_unsynchronized(self, engine, sync, skill):
        """The note says 'unsynchronize it to update': once it is idle again
        the bound value follows the marker, and a new sync sends that."""
        sync(engine, "lru1", through="lru1-1")
        engine.submit(MarkerMove(name="POI-A", value=NEW_POSE))
        taken = engine.plan_unsync(Unsync(robot="lru1"))
        engine.submit(UnsyncDone(robot="lru1", ids=taken))
        engine.release("lru1")
        s = skill(engine, "lru1-1")
        assert (s.status, s.bindings) == (S.IDLE, {"goal": "POI-A"})
        sent = engine.plan_sync(Sync(robot="lru1", through="lru1-1"))
        assert sent[0].params["goal"] == NEW_POSE_D, "the robot gets the marker's current value"
        assert s.params["goal"] == NEW_POSE_D

    def test_skill_in_flight_gets_the_new_value_when_the_sync_fails(self, engine, skill):
        engine.plan_sync(Sync(robot="lru1", through="lru1-1"))
        engine.submit(MarkerMove(name="POI-A", value=NEW_POSE))
        engine.release("lru1", ["lru1-1"])  # robot out of reach: still idle
        sent = engine.plan_sync(Sync(robot="lru1", through="lru1-1"))
        assert sent[0].params["goal"] == NEW_POSE_D
        assert skill(engine, "lru1-1").params["goal"] == NEW_POSE_D

    @pytest.mark.parametrize("status", [S.SUCCESS, S.FAILURE])
    def test_finished_skills_are_neither_changed_nor_reported(self, engine, bring, skill, status):
        bring(engine, "lru1", "lru1-1", status)
        applied = engine.submit(MarkerMove(name="POI-A", value=NEW_POSE))
        assert skill(engine, "lru1-1").params["goal"] == POI_A
        assert applied.value["stale"] == []
        assert applied.notes == []

    def test_skill_being_synchronized_is_reported_and_keeps_what_the_robot_got(self, engine, skill):
        engine.plan_sync(Sync(robot="lru1", through="lru1-1"))
        applied = engine.submit(MarkerMove(name="POI-A", value=NEW_POSE))
        assert "lru1-1" in applied.value["stale"]
        assert any("old value" in n for n in applied.notes)
        # the robot acknowledges what it was sent: the queued skill says so
        engine.submit(SyncAck(robot="lru1", ids=["lru1-1"]))
        engine.release("lru1", ["lru1-1"])
        assert skill(engine, "lru1-1").params["goal"] == POI_A

    @pytest.mark.parametrize(
        "name, value",
        [
            ("POI-A", [Position(x=0), Position(x=1), Position(x=2)]),  # pose marker, polygon given
            ("ROI-1", Pose(x=1.0)),  # area marker, pose given
            ("ROI-1", Position(x=1.0)),
        ],
    )
    def test_kind_mismatch_refused(self, engine, refused, name, value):
        engine.submit(MarkerAdd(name="ROI-1", marker={"kind": "area", "area": AREA}))
        refused(
            engine, lambda: engine.submit(MarkerMove(name=name, value=value)), "bad_marker", name
        )

    def test_unknown_marker_refused(self, engine, refused):
        refused(
            engine,
            lambda: engine.submit(MarkerMove(name="POI-Z", value=NEW_POSE)),
            "unknown_marker",
            "POI-Z",
        )


class TestMarkerRename:
    def test_bindings_follow(self, engine, skill, sync):
        sync(engine, "lru1", through="lru1-1")
        engine.submit(MarkerRename(name="POI-A", new_name="POI-North"))
        assert "POI-A" not in engine.mission.markers
        assert engine.mission.markers["POI-North"].pose == Pose(x=10.0, y=5.0)
        assert skill(engine, "lru1-1").bindings == {"goal": "POI-North"}
        assert skill(engine, "lru1-2").bindings == {"target": "POI-North"}
        assert skill(engine, "lru1-1").params["goal"] == POI_A
        # the renamed marker still drives its bound skills
        engine.submit(MarkerMove(name="POI-North", value=NEW_POSE))
        assert skill(engine, "lru1-2").params["target"] == NEW_POSE_D

    def test_existing_name_refused(self, engine, refused):
        engine.submit(MarkerAdd(name="POI-B", marker={"kind": "pose", "pose": {"x": 1.0}}))
        refused(
            engine,
            lambda: engine.submit(MarkerRename(name="POI-A", new_name="POI-B")),
            "exists",
            "POI-B",
        )

    def test_unknown_marker_refused(self, engine, refused):
        refused(
            engine,
            lambda: engine.submit(MarkerRename(name="POI-Z", new_name="POI-Y")),
            "unknown_marker",
            "POI-Z",
        )


class TestMarkerDelete:
    def test_unbinds_idle_skills_keeping_their_values(self, engine, skill):
        rev = engine.mission.revision
        engine.submit(MarkerDelete(name="POI-A"))
        assert "POI-A" not in engine.mission.markers
        assert engine.mission.revision == rev + 1
        for sid, p in (("lru1-1", "goal"), ("lru1-2", "target")):
            s = skill(engine, sid)
            assert s.bindings == {}
            assert s.params[p] == POI_A

    @pytest.mark.parametrize("status", [S.IDLE_SYNCHRONIZED, S.SYNCHWAITING, S.RUNNING, S.PAUSED])
    def test_refused_while_a_synchronized_skill_uses_it(self, engine, bring, refused, status):
        bring(engine, "lru1", "lru1-1", status)
        refused(
            engine,
            lambda: engine.submit(MarkerDelete(name="POI-A")),
            "marker_in_use",
            "POI-A",
            "lru1-1",
            "lru1",
            robot="lru1",
            skill="lru1-1",
        )

    def test_allowed_when_only_the_log_used_it(self, engine, bring, skill):
        bring(engine, "lru1", "lru1-1", S.SUCCESS)
        engine.submit(MarkerDelete(name="POI-A"))
        assert "POI-A" not in engine.mission.markers
        assert skill(engine, "lru1-1").params["goal"] == POI_A
        assert skill(engine, "lru1-2").bindings == {}

    def test_mission_stays_valid_after_deleting_a_marker_the_log_used(self, engine, sync, report):
        """The mission must still pass the mission-file rules (save, then load
        again): no skill may keep a binding to a marker that is gone."""
        sync(engine, "lru1")
        for sid in ("lru1-1", "lru1-2"):
            report(engine, "lru1", sid, S.RUNNING)
            report(engine, "lru1", sid, S.SUCCESS)
        engine.submit(MarkerDelete(name="POI-A"))
        problems = check_mission(engine.mission.model_copy(deep=True), engine.library, fill=False)
        assert problems == []

    def test_unknown_marker_refused(self, engine, refused):
        refused(
            engine, lambda: engine.submit(MarkerDelete(name="POI-Z")), "unknown_marker", "POI-Z"
        )
