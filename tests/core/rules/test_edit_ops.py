"""Editing the unsynchronized section: add, delete, move, edit.

Only `idle` skills change; parameters are validated against the skill
library with the offending parameter named; every refusal leaves the mission
and its revision untouched (checked by the `refused` helper).
"""

from __future__ import annotations

import re

import pytest

from backend.core.model import ID_PATTERN, Policies, Status
from backend.core.ops import (
    AddBarrier,
    AddSkill,
    DeleteSkills,
    EditSkill,
    MarkerAdd,
    MoveSkill,
    RetryEdit,
    Sync,
)

POI_A = {"x": 10.0, "y": 5.0, "z": 0.0, "roll": 0.0, "pitch": 0.0, "yaw": 0.0}
GOAL = {"x": 1.0, "y": 2.0}
FULL_GOAL = {"x": 1.0, "y": 2.0, "z": 0.0, "roll": 0.0, "pitch": 0.0, "yaw": 0.0}
AREA = {
    "kind": "area",
    "area": [{"x": 0.0, "y": 0.0}, {"x": 4.0, "y": 0.0}, {"x": 4.0, "y": 4.0}],
}


def add(engine, robot="lru1", skill="recharge", **kw):
    return engine.submit(AddSkill(robot=robot, skill=skill, **kw))


# -- add -------------------------------------------------------------------------


class TestAdd:
    def test_appends_at_the_end_of_the_unsynchronized_section(self, engine, ids, skill):
        rev = engine.mission.revision
        applied = add(engine, label="top up")
        sid = applied.value["id"]
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2", sid]
        new = skill(engine, sid)
        assert new.status == Status.IDLE
        assert new.skill == "recharge"
        assert new.label == "top up"
        assert new.attempt == 1
        assert engine.mission.revision == rev + 1 == applied.revision
        assert applied.events, "an applied operation says what changed"

    def test_at_index_within_the_unsynchronized_section(self, engine, ids):
        sid = add(engine, at=0).value["id"]
        assert ids(engine, "lru1") == [sid, "lru1-1", "lru1-2"]
        sid2 = add(engine, at=2).value["id"]
        assert ids(engine, "lru1") == [sid, "lru1-1", sid2, "lru1-2"]

    def test_index_counts_from_the_head_of_the_unsynchronized_section(
        self, engine, sync, ids, status_of
    ):
        sync(engine, "lru1", through="lru1-1")
        sid = add(engine, at=0).value["id"]
        assert ids(engine, "lru1") == ["lru1-1", sid, "lru1-2"]
        assert status_of(engine, "lru1-1") == Status.IDLE_SYNCHRONIZED
        assert status_of(engine, sid) == Status.IDLE

    def test_at_the_end_index_is_allowed(self, engine, ids):
        sid = add(engine, at=2).value["id"]
        assert ids(engine, "lru1")[-1] == sid

    def test_adds_to_a_robot_whose_list_is_fully_synchronized(self, engine, sync, ids):
        sync(engine, "lru1")
        sid = add(engine, at=0).value["id"]
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2", sid]

    @pytest.mark.parametrize("at", [-1, 3, 100])
    def test_bad_index_refused(self, engine, refused, at):
        refused(engine, lambda: add(engine, at=at), "bad_index", "lru1", str(at), robot="lru1")

    def test_bad_index_counts_only_the_unsynchronized_section(self, engine, sync, refused):
        sync(engine, "lru1", through="lru1-1")  # one idle skill left: positions 0..1
        refused(engine, lambda: add(engine, at=2), "bad_index", "lru1", robot="lru1")

    def test_unknown_robot_refused(self, engine, refused):
        refused(engine, lambda: add(engine, robot="lru9"), "unknown_robot", "lru9", robot="lru9")

    @pytest.mark.parametrize(
        "robot, skill_name",
        [
            ("lru1", "pick_stone"),  # a skill of the library, not of this robot type
            ("lru2", "takeoff"),
            ("lru1", "dance"),  # not in the library at all
        ],
    )
    def test_skill_not_offered_by_the_robot_type_refused(self, engine, refused, robot, skill_name):
        r = refused(
            engine,
            lambda: add(engine, robot=robot, skill=skill_name),
            "unknown_skill_type",
            robot,
            skill_name,
            robot=robot,
        )
        # the sentence tells what the robot can do instead
        assert "drive_to" in r.message

    @pytest.mark.parametrize(
        "robot, skill_name, params, param, words",
        [
            ("lru1", "drive_to", {"goal": GOAL, "speed": "fast"}, "speed", ["number"]),
            ("lru1", "drive_to", {"goal": GOAL, "speed": True}, "speed", ["number"]),
            ("lru1", "drive_to", {"goal": GOAL, "speed": 5.0}, "speed", ["maximum"]),
            ("lru1", "drive_to", {"goal": GOAL, "speed": 0.0}, "speed", ["minimum"]),
            ("lru1", "drive_to", {"goal": GOAL, "speed": float("nan")}, "speed", ["finite"]),
            ("lru1", "drive_to", {}, "goal", ["missing", "required"]),
            ("lru1", "drive_to", {"goal": None}, "goal", ["missing"]),
            ("lru1", "drive_to", {"goal": "here"}, "goal", ["pose"]),
            ("lru1", "drive_to", {"goal": {"x": 1.0, "w": 2.0}}, "goal", ["w"]),
            ("lru1", "drive_to", {"goal": {"x": "one"}}, "goal", ["x"]),
            ("lru1", "drive_to", {"goal": GOAL, "colour": "red"}, "colour", ["no parameter"]),
            ("lru1", "take_science_image", {"target": GOAL, "filter": "uv"}, "filter", ["uv"]),
            ("lru1", "take_science_image", {"target": GOAL, "camera": [1]}, "camera", ["mapping"]),
            ("lru1", "explore", {"area": [GOAL, GOAL]}, "area", ["polygon"]),
            (
                "lru1",
                "explore",
                {"area": [GOAL, GOAL, GOAL], "sensors": "lidar"},
                "sensors",
                ["list"],
            ),
            (
                "lru1",
                "explore",
                {"area": [GOAL, GOAL, GOAL], "return_to_start": 1},
                "return_to_start",
                ["true or false"],
            ),
            ("lru2", "identify_stone", {"target": GOAL, "partner": "lru9"}, "partner", ["lru9"]),
            ("lru2", "pick_stone", {"target": GOAL, "region": "nowhere"}, "region", ["nowhere"]),
            (
                "lru2",
                "pick_stone",
                {"target": GOAL, "region": "POI-A"},
                "region",
                ["POI-A", "area"],
            ),
            ("lru2", "pick_payload_box", {"box": 3}, "box", []),
        ],
    )
    def test_bad_parameter_refused_naming_it(
        self, engine, refused, robot, skill_name, params, param, words
    ):
        r = refused(
            engine,
            lambda: add(engine, robot=robot, skill=skill_name, params=params),
            "bad_param",
            robot,
            skill_name,
            param,
            *words,
            robot=robot,
            param=param,
        )
        assert r.to_dict()["param"] == param

    def test_every_parameter_problem_is_named(self, engine, refused):
        # the missing goal comes first; the bad speed must not hide behind "(and 1 more)"
        r = refused(
            engine,
            lambda: add(engine, skill="drive_to", params={"speed": "fast"}),
            "bad_param",
            robot="lru1",
            param="goal",
        )
        assert re.fullmatch(
            r"lru1, skill drive_to, parameter goal: [^;]+; parameter speed: [^;]*'fast'[^;]*",
            r.message,
        ), r.message

    @pytest.mark.parametrize(
        "slot, words", [(1.5, ["integer"]), (True, ["integer"]), (5, ["maximum"]), (0, ["minimum"])]
    )
    def test_int_parameter_of_a_static_robot(self, engine3, refused, slot, words):
        refused(
            engine3,
            lambda: add(
                engine3,
                robot="lander",
                skill="load_box",
                params={"box": "sample_box", "slot": slot},
            ),
            "bad_param",
            "lander",
            "slot",
            *words,
            robot="lander",
            param="slot",
        )

    def test_static_robot_skill_with_int_parameter(self, engine3, skill):
        sid = add(engine3, robot="lander", skill="load_box", params={"box": "wifi_box_1"}).value[
            "id"
        ]
        assert skill(engine3, sid).params == {"box": "wifi_box_1", "slot": 1}

    def test_binding_gives_the_marker_value(self, engine, skill):
        sid = add(engine, robot="lru2", skill="drive_to", bindings={"goal": "POI-A"}).value["id"]
        s = skill(engine, sid)
        assert s.bindings == {"goal": "POI-A"}
        assert s.params["goal"] == POI_A

    def test_binding_a_position_parameter_to_a_pose_marker(self, engine, skill):
        sid = add(engine, robot="lru2", skill="identify_stone", bindings={"target": "POI-A"}).value[
            "id"
        ]
        assert skill(engine, sid).params["target"] == {"x": 10.0, "y": 5.0, "z": 0.0}

    def test_binding_an_area_parameter(self, engine, skill):
        engine.submit(MarkerAdd(name="ROI-1", marker=AREA))
        sid = add(engine, skill="explore", bindings={"area": "ROI-1"}).value["id"]
        assert skill(engine, sid).params["area"] == [
            {"x": 0.0, "y": 0.0, "z": 0.0},
            {"x": 4.0, "y": 0.0, "z": 0.0},
            {"x": 4.0, "y": 4.0, "z": 0.0},
        ]

    @pytest.mark.parametrize(
        "skill_name, bindings, param, words",
        [
            (
                "drive_to",
                {"goal": "NOWHERE"},
                "goal",
                ["unknown marker 'NOWHERE' (markers: POI-A, ROI-1)"],
            ),
            ("drive_to", {"goal": "ROI-1"}, "goal", ["ROI-1"]),  # area marker cannot give a pose
            ("explore", {"area": "POI-A"}, "area", ["POI-A"]),  # pose marker cannot give an area
            (
                "recharge",
                {"target_level": "POI-A"},
                "target_level",
                [],
            ),  # not a geometric parameter
            ("recharge", {"colour": "POI-A"}, "colour", []),  # no such parameter
        ],
    )
    def test_bad_binding_refused_naming_the_parameter(
        self, engine, refused, skill_name, bindings, param, words
    ):
        engine.submit(MarkerAdd(name="ROI-1", marker=AREA))
        refused(
            engine,
            lambda: add(engine, skill=skill_name, bindings=bindings),
            "bad_param",
            "lru1",
            param,
            *words,
            robot="lru1",
            param=param,
        )

    def test_defaults_are_filled_and_values_normalized(self, engine, skill):
        sid = add(engine, skill="drive_to", params={"goal": GOAL, "speed": 1}).value["id"]
        s = skill(engine, sid)
        assert s.params == {"goal": FULL_GOAL, "speed": 1.0, "tolerance": 0.5}
        assert isinstance(s.params["speed"], float)

    def test_optional_parameter_without_default_may_be_left_out(self, engine, skill):
        sid = add(engine, robot="lru2", skill="identify_stone", params={"target": GOAL}).value["id"]
        s = skill(engine, sid)
        assert "partner" not in s.params
        assert s.params["search_radius"] == 8.0  # the library's default

    def test_policies_are_kept(self, engine, skill):
        pol = Policies(retries=2, pause_out_of_comms=True, recharge_below=0.2)
        sid = add(engine, policies=pol).value["id"]
        assert skill(engine, sid).policies == pol

    def test_ids_are_unique_and_never_reused(self, engine, ids):
        before = engine.mission.all_ids()
        a = add(engine).value["id"]
        b = add(engine, robot="lru2", skill="recharge").value["id"]
        engine.submit(DeleteSkills(ids=[a]))
        c = add(engine).value["id"]
        assert len({a, b, c}) == 3
        assert not {a, b, c} & before
        for sid in (a, b, c):
            assert re.match(ID_PATTERN, sid)

    def test_ids_are_stable_across_move_edit_and_sync(self, engine, sync, ids, status_of):
        sid = add(engine).value["id"]
        engine.submit(MoveSkill(id=sid, index=0))
        engine.submit(EditSkill(id=sid, label="renamed", params={"target_level": 0.5}))
        assert ids(engine, "lru1") == [sid, "lru1-1", "lru1-2"]
        sync(engine, "lru1", through=sid)
        assert ids(engine, "lru1") == [sid, "lru1-1", "lru1-2"]
        assert status_of(engine, sid) == Status.IDLE_SYNCHRONIZED

    def test_add_before_a_skill_being_synchronized_refused(self, engine, refused):
        engine.plan_sync(Sync(robot="lru1", through="lru1-1"))
        refused(engine, lambda: add(engine, at=0), "locked", "lru1-1", "lru1", robot="lru1")

    def test_add_after_skills_being_synchronized_allowed(self, engine, ids):
        engine.plan_sync(Sync(robot="lru1", through="lru1-1"))
        sid = add(engine, at=1).value["id"]
        assert ids(engine, "lru1") == ["lru1-1", sid, "lru1-2"]


# -- delete ----------------------------------------------------------------------


class TestDelete:
    def test_deletes_idle_skills(self, engine, ids):
        rev = engine.mission.revision
        engine.submit(DeleteSkills(ids=["lru1-1"]))
        assert ids(engine, "lru1") == ["lru1-2"]
        assert engine.mission.revision == rev + 1

    def test_deletes_several_skills_of_several_robots_at_once(self, engine, ids):
        engine.submit(DeleteSkills(ids=["lru1-2", "lru2-1", "lru1-1"]))
        assert ids(engine, "lru1") == []
        assert ids(engine, "lru2") == ["lru2-2"]

    @pytest.mark.parametrize(
        ("status", "remedy"),
        [
            (Status.IDLE_SYNCHRONIZED, "unsynchronize it first"),
            (
                Status.SYNCHWAITING,
                "stop the robot (the skill goes back to its queue), then unsynchronize it",
            ),
            (Status.RUNNING, "stop the robot"),
            (Status.PAUSED, "stop the robot"),
            (Status.SUCCESS, "the execution log and never change"),
            (Status.FAILURE, "retry a failed one"),
        ],
    )
    def test_non_idle_refused_with_what_to_do(self, engine, refused, bring, status, remedy):
        bring(engine, "lru1", "lru1-1", status)
        refused(
            engine,
            lambda: engine.submit(DeleteSkills(ids=["lru1-1"])),
            "not_idle",
            "lru1-1",
            "lru1",
            status.value,
            remedy,
            robot="lru1",
            skill="lru1-1",
        )

    def test_refusal_is_atomic(self, engine, sync, refused, ids):
        sync(engine, "lru1", through="lru1-1")
        refused(
            engine,
            lambda: engine.submit(DeleteSkills(ids=["lru1-2", "lru2-1", "lru1-1"])),
            "not_idle",
            "lru1-1",
        )
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2"]
        assert ids(engine, "lru2") == ["lru2-1", "lru2-2"]

    def test_locked_while_being_synchronized(self, engine, refused, ids):
        engine.plan_sync(Sync(robot="lru1", through="lru1-1"))
        refused(
            engine,
            lambda: engine.submit(DeleteSkills(ids=["lru1-1"])),
            "locked",
            "lru1-1",
            "lru1",
            robot="lru1",
            skill="lru1-1",
        )
        # a skill after the one in flight stays editable
        engine.submit(DeleteSkills(ids=["lru1-2"]))
        assert ids(engine, "lru1") == ["lru1-1"]

    def test_deletable_again_after_the_sync_is_released_unanswered(self, engine, ids):
        sent = engine.plan_sync(Sync(robot="lru1", through="lru1-1"))
        engine.release("lru1", [s.id for s in sent])  # robot out of reach
        engine.submit(DeleteSkills(ids=["lru1-1"]))
        assert ids(engine, "lru1") == ["lru1-2"]

    def test_unknown_id_refused(self, engine, refused):
        refused(
            engine,
            lambda: engine.submit(DeleteSkills(ids=["lru1-1", "nope-7"])),
            "unknown_skill",
            "nope-7",
            skill="nope-7",
        )

    def test_removes_the_skill_from_its_barrier(self, engine3):
        a = engine3.ardea_first
        bid = engine3.submit(AddBarrier(ids=["lru1-1", "lru2-1", a])).value["barrier"]
        engine3.submit(DeleteSkills(ids=["lru1-1"]))
        assert engine3.mission.barriers[bid].skills == ["lru2-1", a]
        assert engine3.mission.barrier_of("lru1-1") is None

    def test_barrier_left_with_one_skill_dissolves(self, engine):
        bid = engine.submit(AddBarrier(ids=["lru1-1", "lru2-1"])).value["barrier"]
        engine.submit(DeleteSkills(ids=["lru1-1"]))
        assert bid not in engine.mission.barriers
        assert engine.mission.barrier_of("lru2-1") is None

    def test_barrier_left_with_one_robot_dissolves(self, engine3):
        a = engine3.ardea_first
        bid = engine3.submit(AddBarrier(ids=["lru1-1", "lru2-1", a])).value["barrier"]
        engine3.submit(DeleteSkills(ids=["lru2-1", a]))
        assert bid not in engine3.mission.barriers

    def test_deleting_every_member_removes_the_barrier(self, engine):
        bid = engine.submit(AddBarrier(ids=["lru1-1", "lru2-1"])).value["barrier"]
        engine.submit(DeleteSkills(ids=["lru1-1", "lru2-1"]))
        assert bid not in engine.mission.barriers

    def test_partner_already_synchronized_refused(self, engine, sync, refused):
        bid = engine.submit(AddBarrier(ids=["lru1-1", "lru2-1"])).value["barrier"]
        sync(engine, "lru2", through="lru2-1")
        r = refused(
            engine,
            lambda: engine.submit(DeleteSkills(ids=["lru1-1"])),
            "barrier_partner_synchronized",
            "lru1-1",
            "lru2-1",
            "lru2",
            bid,
            skill="lru2-1",
            robot="lru2",
        )
        assert "unsynchronize" in r.message
        assert engine.mission.barriers[bid].skills == ["lru1-1", "lru2-1"]

    def test_partner_that_finished_does_not_block_the_delete(self, engine, sync, report, status_of):
        """The partner failed while waiting at the barrier: it can never be
        unsynchronized (the log is immutable), so it must not pin the idle
        skill forever."""
        bid = engine.submit(AddBarrier(ids=["lru1-1", "lru2-1"])).value["barrier"]
        sync(engine, "lru2", through="lru2-1")
        report(engine, "lru2", "lru2-1", Status.SYNCHWAITING)
        report(engine, "lru2", "lru2-1", Status.FAILURE, info="partner never came")
        engine.submit(DeleteSkills(ids=["lru1-1"]))
        assert engine.mission.find("lru1-1") is None
        assert bid not in engine.mission.barriers
        assert status_of(engine, "lru2-1") == Status.FAILURE


# -- move ------------------------------------------------------------------------


class TestMove:
    def test_moves_within_the_unsynchronized_section(self, engine, ids):
        rev = engine.mission.revision
        engine.submit(MoveSkill(id="lru1-2", index=0))
        assert ids(engine, "lru1") == ["lru1-2", "lru1-1"]
        assert engine.mission.revision == rev + 1
        engine.submit(MoveSkill(id="lru1-2", index=1))
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2"]

    def test_index_counts_from_the_head_of_the_unsynchronized_section(self, engine, sync, ids):
        a = add(engine).value["id"]
        sync(engine, "lru1", through="lru1-1")
        engine.submit(MoveSkill(id=a, index=0))
        assert ids(engine, "lru1") == ["lru1-1", a, "lru1-2"]

    def test_moving_to_the_same_place_changes_nothing(self, engine, snapshot):
        before = snapshot(engine)
        applied = engine.submit(MoveSkill(id="lru1-1", index=0))
        assert snapshot(engine) == before
        assert applied.revision == before["mission"]["revision"]
        assert applied.events == []

    @pytest.mark.parametrize("index", [2, 50])
    def test_bad_index_refused(self, engine, refused, index):
        refused(
            engine,
            lambda: engine.submit(MoveSkill(id="lru1-1", index=index)),
            "bad_index",
            "lru1",
            str(index),
            robot="lru1",
        )

    def test_cannot_move_into_the_synchronized_section(self, engine, sync, refused):
        sync(engine, "lru1", through="lru1-1")
        refused(engine, lambda: engine.submit(MoveSkill(id="lru1-2", index=1)), "bad_index", "lru1")

    @pytest.mark.parametrize("status", [Status.IDLE_SYNCHRONIZED, Status.RUNNING, Status.SUCCESS])
    def test_non_idle_refused(self, engine, refused, bring, status):
        bring(engine, "lru1", "lru1-1", status)
        refused(
            engine,
            lambda: engine.submit(MoveSkill(id="lru1-1", index=0)),
            "not_idle",
            "lru1-1",
            "lru1",
            robot="lru1",
            skill="lru1-1",
        )

    def test_locked_while_being_synchronized(self, engine, refused):
        engine.plan_sync(Sync(robot="lru1", through="lru1-1"))
        refused(
            engine,
            lambda: engine.submit(MoveSkill(id="lru1-1", index=1)),
            "locked",
            "lru1-1",
            skill="lru1-1",
        )
        # nothing may be put in front of a skill in flight either
        refused(
            engine,
            lambda: engine.submit(MoveSkill(id="lru1-2", index=0)),
            "locked",
            "lru1-1",
            robot="lru1",
        )

    def test_unknown_id_refused(self, engine, refused):
        refused(
            engine,
            lambda: engine.submit(MoveSkill(id="nope-1", index=0)),
            "unknown_skill",
            "nope-1",
        )


# -- edit ------------------------------------------------------------------------


class TestEdit:
    def test_label(self, engine, skill):
        rev = engine.mission.revision
        engine.submit(EditSkill(id="lru2-1", label="closer"))
        s = skill(engine, "lru2-1")
        assert s.label == "closer"
        assert s.params["goal"] == {
            "x": 9.0,
            "y": 4.0,
            "z": 0.0,
            "roll": 0.0,
            "pitch": 0.0,
            "yaw": 0.0,
        }
        assert engine.mission.revision == rev + 1

    def test_params_are_merged(self, engine, skill):
        before = skill(engine, "lru2-1").params
        engine.submit(EditSkill(id="lru2-1", params={"speed": 0.8}))
        after = skill(engine, "lru2-1").params
        assert after == {**before, "speed": 0.8}

    def test_none_resets_an_optional_parameter_to_its_default(self, engine, skill):
        engine.submit(EditSkill(id="lru2-1", params={"speed": 0.8}))
        engine.submit(EditSkill(id="lru2-1", params={"speed": None}))
        assert skill(engine, "lru2-1").params["speed"] == 0.5

    def test_typed_value_replaces_a_binding(self, engine, skill):
        engine.submit(EditSkill(id="lru1-1", params={"goal": GOAL}))
        s = skill(engine, "lru1-1")
        assert "goal" not in s.bindings
        assert s.params["goal"] == FULL_GOAL

    def test_unbinding_keeps_the_current_value(self, engine, skill):
        engine.submit(EditSkill(id="lru1-1", bindings={"goal": None}))
        s = skill(engine, "lru1-1")
        assert s.bindings == {}
        assert s.params["goal"] == POI_A

    def test_binding_takes_the_marker_value(self, engine, skill):
        engine.submit(EditSkill(id="lru2-1", bindings={"goal": "POI-A"}))
        s = skill(engine, "lru2-1")
        assert s.bindings == {"goal": "POI-A"}
        assert s.params["goal"] == POI_A

    def test_policies(self, engine, skill):
        pol = Policies(retries=3, recharge_below=0.25)
        engine.submit(EditSkill(id="lru1-1", policies=pol))
        assert skill(engine, "lru1-1").policies == pol
        # an edit without policies keeps them
        engine.submit(EditSkill(id="lru1-1", label="x"))
        assert skill(engine, "lru1-1").policies == pol

    def test_edit_that_changes_nothing_keeps_the_revision(self, engine, snapshot):
        before = snapshot(engine)
        applied = engine.submit(
            EditSkill(id="lru2-1", label="drive next to POI-A", params={"speed": 0.5})
        )
        assert applied.events == []
        assert snapshot(engine) == before

    @pytest.mark.parametrize(
        "status",
        [
            Status.IDLE_SYNCHRONIZED,
            Status.SYNCHWAITING,
            Status.RUNNING,
            Status.PAUSED,
            Status.SUCCESS,
            Status.FAILURE,
        ],
    )
    def test_non_idle_refused(self, engine, refused, bring, status):
        bring(engine, "lru1", "lru1-1", status)
        r = refused(
            engine,
            lambda: engine.submit(EditSkill(id="lru1-1", label="x")),
            "not_idle",
            "lru1-1",
            "lru1",
            status.value,
            robot="lru1",
            skill="lru1-1",
        )
        if status == Status.IDLE_SYNCHRONIZED:
            assert "unsynchronize" in r.message

    def test_locked_while_being_synchronized(self, engine, refused):
        engine.plan_sync(Sync(robot="lru1", through="lru1-1"))
        refused(
            engine,
            lambda: engine.submit(EditSkill(id="lru1-1", label="x")),
            "locked",
            "lru1-1",
            "lru1",
            skill="lru1-1",
        )

    @pytest.mark.parametrize(
        "params, bindings, param",
        [
            ({"speed": 9.0}, {}, "speed"),
            ({"speed": "slow"}, {}, "speed"),
            ({"goal": {"x": 1.0, "q": 0.0}}, {}, "goal"),
            ({"colour": "red"}, {}, "colour"),
            ({}, {"goal": "NOWHERE"}, "goal"),
            ({"goal": None}, {}, "goal"),  # required: cannot be cleared
        ],
    )
    def test_invalid_parameter_refused_naming_it(self, engine, refused, params, bindings, param):
        refused(
            engine,
            lambda: engine.submit(EditSkill(id="lru2-1", params=params, bindings=bindings)),
            "bad_param",
            "lru2",
            "lru2-1",
            param,
            robot="lru2",
            skill="lru2-1",
            param=param,
        )

    def test_unknown_id_refused(self, engine, refused):
        refused(
            engine,
            lambda: engine.submit(EditSkill(id="nope-1", label="x")),
            "unknown_skill",
            "nope-1",
        )


# -- edit and retry: the next attempt, idle, to edit before it is synchronized -----------


class TestRetryEdit:
    def fail_first(self, engine, sync, report):
        sync(engine, "lru1")
        report(engine, "lru1", "lru1-1", Status.RUNNING)
        report(engine, "lru1", "lru1-1", Status.FAILURE, info="wheel stuck")

    def test_an_idle_copy_heads_the_plan_with_the_next_attempt(
        self, engine, sync, report, ids, skill
    ):
        engine.submit(EditSkill(id="lru1-1", label="drive out", policies=Policies(retries=2)))
        self.fail_first(engine, sync, report)
        applied = engine.submit(RetryEdit(id="lru1-1"))
        assert applied.value == {"id": "lru1-1.2"}
        new, failed = skill(engine, "lru1-1.2"), skill(engine, "lru1-1")
        assert (new.status, new.attempt, new.label) == (Status.IDLE, 2, "drive out")
        assert (new.params, new.bindings, new.policies) == (
            failed.params,
            failed.bindings,
            failed.policies,
        )
        assert failed.status == Status.FAILURE  # the log keeps the failed attempt
        # the head of the unsynchronized section: after the queued lru1-2
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2", "lru1-1.2"]
        # it is an ordinary idle skill: edited, then synchronized
        engine.submit(EditSkill(id="lru1-1.2", params={"speed": 0.2}))
        assert skill(engine, "lru1-1.2").params["speed"] == 0.2
        # and undone like an add
        engine.submit(DeleteSkills(ids=["lru1-1.2"]))
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2"]

    def test_refused_unless_failed_and_not_yet_retried(self, engine, sync, report, refused):
        refused(engine, lambda: engine.submit(RetryEdit(id="lru1-1")), "cannot_retry", "idle")
        self.fail_first(engine, sync, report)
        engine.submit(RetryEdit(id="lru1-1"))
        refused(engine, lambda: engine.submit(RetryEdit(id="lru1-1")), "cannot_retry", "lru1-1.2")
