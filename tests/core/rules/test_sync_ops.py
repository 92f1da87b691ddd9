"""Synchronization and unsynchronization: two-phase operations.

`plan_sync` / `plan_unsync` say what to send and change nothing in the
mission; the robot's `SyncAck` / `UnsyncDone` is what changes statuses.
"""

from __future__ import annotations

import pytest

from backend.core.model import Status
from backend.core.ops import (
    AddBarrier,
    AddSkill,
    Control,
    DeleteSkills,
    EditSkill,
    MoveSkill,
    Retry,
    Sync,
    SyncAck,
    Unsync,
    UnsyncDone,
)


def plan_sync(engine, robot="lru1", through=None):
    return engine.plan_sync(Sync(robot=robot, through=through))


def plan_unsync(engine, robot="lru1", from_id=None):
    return engine.plan_unsync(Unsync(robot=robot, from_id=from_id))


# -- plan_sync ---------------------------------------------------------------------


class TestPlanSync:
    def test_through_a_skill_sends_it_and_those_before_it(self, engine, snapshot):
        before = snapshot(engine)["mission"]
        sent = plan_sync(engine, through="lru1-1")
        assert [s.id for s in sent] == ["lru1-1"]
        assert snapshot(engine)["mission"] == before, "planning changes nothing in the mission"

        engine.release("lru1", ["lru1-1"])
        sent = plan_sync(engine, through="lru1-2")
        assert [s.id for s in sent] == ["lru1-1", "lru1-2"]

    def test_without_through_sends_every_idle_skill(self, engine, sync, status_of):
        sent = plan_sync(engine)
        assert [s.id for s in sent] == ["lru1-1", "lru1-2"]
        assert all(s.status == Status.IDLE for s in sent)
        engine.submit(SyncAck(robot="lru1", ids=["lru1-1", "lru1-2"]))
        engine.release("lru1", ["lru1-1", "lru1-2"])
        assert (
            status_of(engine, "lru1-1") == status_of(engine, "lru1-2") == Status.IDLE_SYNCHRONIZED
        )
        # the other robot is untouched
        assert status_of(engine, "lru2-1") == Status.IDLE

    def test_sent_skills_carry_their_parameters(self, engine, skill):
        sent = plan_sync(engine, through="lru1-1")
        assert sent[0].params == skill(engine, "lru1-1").params
        assert sent[0].skill == "drive_to"

    def test_sent_skills_are_copies(self, engine, skill):
        sent = plan_sync(engine, through="lru1-1")
        sent[0].params["speed"] = 0.9
        assert skill(engine, "lru1-1").params["speed"] == 0.5

    def test_continues_after_the_synchronized_section(self, engine, sync):
        sync(engine, "lru1", through="lru1-1")
        sent = plan_sync(engine)
        assert [s.id for s in sent] == ["lru1-2"]

    def test_nothing_to_sync_refused(self, engine, sync, refused):
        sync(engine, "lru1")
        refused(engine, lambda: plan_sync(engine), "nothing_to_sync", "lru1", robot="lru1")

    def test_nothing_to_sync_on_an_empty_list(self, engine, refused):
        engine.submit(DeleteSkills(ids=["lru1-1", "lru1-2"]))
        refused(engine, lambda: plan_sync(engine), "nothing_to_sync", "lru1", robot="lru1")

    def test_through_a_skill_of_another_robot_refused(self, engine, refused):
        refused(
            engine,
            lambda: plan_sync(engine, through="lru2-1"),
            "wrong_robot",
            "lru2-1",
            "lru1",
            "lru2",
            robot="lru1",
            skill="lru2-1",
        )

    def test_through_a_non_idle_skill_refused(self, engine, sync, refused):
        sync(engine, "lru1", through="lru1-1")
        refused(
            engine,
            lambda: plan_sync(engine, through="lru1-1"),
            "not_idle",
            "lru1-1",
            "lru1",
            "idle_synchronized",
            robot="lru1",
            skill="lru1-1",
        )

    def test_through_an_unknown_skill_refused(self, engine, refused):
        refused(engine, lambda: plan_sync(engine, through="nope-3"), "unknown_skill", "nope-3")

    def test_unknown_robot_refused(self, engine, refused):
        refused(
            engine, lambda: plan_sync(engine, robot="lru9"), "unknown_robot", "lru9", robot="lru9"
        )


@pytest.mark.parametrize(
    "op, method",
    [
        (Sync(robot="lru1"), "plan_sync"),
        (Unsync(robot="lru1"), "plan_unsync"),
        (Control(op="run", robot="lru1"), "plan_control"),
        (Control(op="pause", robot="lru2"), "plan_control"),
    ],
    ids=["sync", "unsync", "run", "pause"],
)
def test_submitted_robot_operations_queue_a_command_instead(engine, sync, report, op, method):
    """Submitted (not planned), an operation on a robot adds a command to the
    robot's uplink and changes no skill: the robot's answer will (protocol 2;
    the direct path, planning, is for tools and tests that play the robot)."""
    sync(engine, "lru1", through="lru1-1")
    sync(engine, "lru2", through="lru2-1")
    report(engine, "lru2", "lru2-1", "running")
    tasks = engine.mission.model_dump(mode="json")["tasks"]
    applied = engine.submit(op, client="c1")
    assert engine.mission.model_dump(mode="json")["tasks"] == tasks
    [command] = engine.mission.pending_commands()
    assert command.op == op.op and applied.revision == engine.mission.revision


class TestInFlight:
    def test_sent_skills_are_locked_until_the_ack(self, engine, refused, skill, status_of):
        plan_sync(engine, through="lru1-1")
        for op in (
            EditSkill(id="lru1-1", label="x"),
            DeleteSkills(ids=["lru1-1"]),
            MoveSkill(id="lru1-1", index=1),
            MoveSkill(id="lru1-2", index=0),
            AddSkill(robot="lru1", skill="recharge", at=0),
            AddBarrier(ids=["lru1-1", "lru2-1"]),
        ):
            refused(engine, lambda op=op: engine.submit(op), "locked", "lru1-1")
        # skills after the ones in flight stay editable
        engine.submit(EditSkill(id="lru1-2", label="still editable"))
        assert skill(engine, "lru1-2").label == "still editable"
        engine.submit(SyncAck(robot="lru1", ids=["lru1-1"]))
        assert status_of(engine, "lru1-1") == Status.IDLE_SYNCHRONIZED
        # now synchronized: refused for that reason, not the lock
        refused(
            engine, lambda: engine.submit(EditSkill(id="lru1-1", label="x")), "not_idle", "lru1-1"
        )

    def test_release_without_ack_changes_nothing_and_unlocks(self, engine, snapshot, skill):
        before = snapshot(engine)
        plan_sync(engine, through="lru1-2")
        engine.release("lru1", ["lru1-1", "lru1-2"])  # robot out of reach
        assert snapshot(engine) == before
        engine.submit(EditSkill(id="lru1-1", label="editable again"))
        assert skill(engine, "lru1-1").label == "editable again"
        assert [s.id for s in plan_sync(engine)] == ["lru1-1", "lru1-2"]

    def test_robot_busy_while_a_command_is_pending(self, engine, sync, refused):
        sync(engine, "lru1", through="lru1-1")
        plan_sync(engine, through="lru1-2")
        refused(engine, lambda: plan_sync(engine), "robot_busy", "lru1", robot="lru1")
        refused(engine, lambda: plan_unsync(engine), "robot_busy", "lru1", robot="lru1")
        refused(
            engine,
            lambda: engine.plan_control(Control(op="reset", robot="lru1")),
            "robot_busy",
            "lru1",
            robot="lru1",
        )
        # the other robot is free
        assert [s.id for s in plan_sync(engine, robot="lru2")] == ["lru2-1", "lru2-2"]

    def test_robot_busy_ends_with_release(self, engine):
        plan_sync(engine, through="lru1-1")
        engine.release("lru1", ["lru1-1"])
        assert [s.id for s in plan_sync(engine, through="lru1-1")] == ["lru1-1"]

    def test_robot_busy_for_retry(self, engine, bring, refused):
        bring(engine, "lru1", "lru1-1", Status.FAILURE)
        plan_sync(engine, through="lru1-2")
        refused(
            engine,
            lambda: engine.plan_retry(Retry(id="lru1-1")),
            "robot_busy",
            "lru1",
            robot="lru1",
        )


class TestSyncAck:
    def test_applies_idle_synchronized_in_order(self, engine, ids, status_of):
        a = engine.submit(AddSkill(robot="lru1", skill="recharge")).value["id"]
        sent = plan_sync(engine, through="lru1-2")
        rev = engine.mission.revision
        applied = engine.submit(SyncAck(robot="lru1", ids=[s.id for s in sent]))
        assert applied.revision == rev + 1 == engine.mission.revision
        assert applied.value["synchronized"] == ["lru1-1", "lru1-2"]
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2", a]
        assert [status_of(engine, i) for i in ids(engine, "lru1")] == [
            Status.IDLE_SYNCHRONIZED,
            Status.IDLE_SYNCHRONIZED,
            Status.IDLE,
        ]

    @pytest.mark.parametrize(
        "acked",
        [
            ["lru1-2"],  # skips the head of the unsynchronized section
            ["lru1-2", "lru1-1"],  # out of order
            ["lru2-1"],  # another robot's skill
            ["nope-1"],
        ],
    )
    def test_bad_ack_refused(self, engine, refused, acked):
        plan_sync(engine)
        refused(
            engine,
            lambda: engine.submit(SyncAck(robot="lru1", ids=acked)),
            "bad_report",
            "lru1",
            robot="lru1",
        )

    def test_ack_of_already_synchronized_skills_refused(self, engine, sync, refused):
        sync(engine, "lru1", through="lru1-1")
        refused(
            engine,
            lambda: engine.submit(SyncAck(robot="lru1", ids=["lru1-1"])),
            "bad_report",
            "lru1-1",
        )

    def test_late_ack_after_the_sync_was_given_up_refused(self, engine, refused, skill):
        """The sync timed out (released unanswered) and the operator edited the
        skill: a late acknowledgement must not mark the edited skill as on the
        robot, which holds the old version."""
        plan_sync(engine, through="lru1-1")
        engine.release("lru1", ["lru1-1"])
        engine.submit(EditSkill(id="lru1-1", params={"speed": 0.9}))
        refused(
            engine,
            lambda: engine.submit(SyncAck(robot="lru1", ids=["lru1-1"])),
            "bad_report",
            "lru1-1",
        )
        assert skill(engine, "lru1-1").status == Status.IDLE

    def test_ack_for_an_unknown_robot_refused(self, engine, refused):
        refused(
            engine,
            lambda: engine.submit(SyncAck(robot="lru9", ids=["lru1-1"])),
            "unknown_robot",
            "lru9",
        )


# -- plan_unsync / UnsyncDone ----------------------------------------------------------


class TestUnsync:
    def test_from_a_queued_skill_to_the_end(self, engine, sync, snapshot):
        sync(engine, "lru1")
        before = snapshot(engine)["mission"]
        assert plan_unsync(engine, from_id="lru1-2") == ["lru1-2"]
        assert snapshot(engine)["mission"] == before
        engine.release("lru1")
        assert plan_unsync(engine, from_id="lru1-1") == ["lru1-1", "lru1-2"]

    def test_all_queued(self, engine, sync, bring):
        bring(engine, "lru1", "lru1-1", Status.RUNNING)
        sync(engine, "lru1")
        # the running skill is not queued: only lru1-2 is taken back
        assert plan_unsync(engine) == ["lru1-2"]

    def test_nothing_queued_refused(self, engine, refused, bring):
        refused(engine, lambda: plan_unsync(engine), "nothing_to_unsync", "lru1", robot="lru1")
        bring(engine, "lru1", "lru1-1", Status.RUNNING)
        refused(engine, lambda: plan_unsync(engine), "nothing_to_unsync", "lru1", robot="lru1")

    @pytest.mark.parametrize(
        "status",
        [Status.RUNNING, Status.PAUSED, Status.SYNCHWAITING, Status.SUCCESS, Status.FAILURE],
    )
    def test_from_a_non_queued_skill_refused(self, engine, sync, bring, refused, status):
        bring(engine, "lru1", "lru1-1", status)
        sync(engine, "lru1")
        refused(
            engine,
            lambda: plan_unsync(engine, from_id="lru1-1"),
            "not_queued",
            "lru1-1",
            "lru1",
            status.value,
            robot="lru1",
            skill="lru1-1",
        )

    def test_from_an_idle_skill_refused(self, engine, sync, refused):
        sync(engine, "lru1", through="lru1-1")
        refused(
            engine,
            lambda: plan_unsync(engine, from_id="lru1-2"),
            "not_queued",
            "lru1-2",
            "idle",
            skill="lru1-2",
        )

    def test_from_a_skill_of_another_robot_refused(self, engine, sync, refused):
        sync(engine, "lru1")
        sync(engine, "lru2")
        refused(
            engine,
            lambda: plan_unsync(engine, from_id="lru2-1"),
            "wrong_robot",
            "lru2-1",
            "lru1",
            skill="lru2-1",
        )

    def test_from_an_unknown_skill_refused(self, engine, sync, refused):
        sync(engine, "lru1")
        refused(engine, lambda: plan_unsync(engine, from_id="nope-2"), "unknown_skill", "nope-2")

    def test_unknown_robot_refused(self, engine, refused):
        refused(engine, lambda: plan_unsync(engine, robot="lru9"), "unknown_robot", "lru9")

    def test_done_returns_skills_to_the_head_of_the_unsynchronized_section_in_order(
        self, engine, sync, ids, status_of
    ):
        sync(engine, "lru1")
        c = engine.submit(AddSkill(robot="lru1", skill="recharge")).value["id"]
        taken = plan_unsync(engine)
        rev = engine.mission.revision
        applied = engine.submit(UnsyncDone(robot="lru1", ids=taken))
        engine.release("lru1")
        assert applied.revision == rev + 1
        assert applied.value["unsynchronized"] == ["lru1-1", "lru1-2"]
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2", c]
        assert all(status_of(engine, i) == Status.IDLE for i in ids(engine, "lru1"))

    def test_partial_unsync_keeps_the_head_of_the_queue(self, engine, sync, ids, status_of):
        c = engine.submit(AddSkill(robot="lru1", skill="recharge")).value["id"]
        sync(engine, "lru1", through="lru1-2")
        taken = plan_unsync(engine, from_id="lru1-2")
        engine.submit(UnsyncDone(robot="lru1", ids=taken))
        engine.release("lru1")
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2", c]
        assert [status_of(engine, i) for i in ids(engine, "lru1")] == [
            Status.IDLE_SYNCHRONIZED,
            Status.IDLE,
            Status.IDLE,
        ]

    def test_unsynchronized_skills_are_editable_again(self, engine, sync, skill):
        sync(engine, "lru1")
        engine.submit(UnsyncDone(robot="lru1", ids=plan_unsync(engine)))
        engine.release("lru1")
        engine.submit(EditSkill(id="lru1-2", label="changed"))
        engine.submit(MoveSkill(id="lru1-2", index=0))
        assert skill(engine, "lru1-2").label == "changed"

    @pytest.mark.parametrize(
        "removed",
        [
            ["lru1-1"],  # not the end of the queue
            ["lru1-2", "lru1-1"],  # out of order
            ["lru1-1", "lru1-2", "lru1-3"],  # more than is queued
            ["lru2-1"],
        ],
    )
    def test_bad_unsync_done_refused(self, engine, sync, refused, removed):
        engine.submit(AddSkill(robot="lru1", skill="recharge"))  # lru1-3, idle
        sync(engine, "lru1", through="lru1-2")
        plan_unsync(engine)
        refused(
            engine,
            lambda: engine.submit(UnsyncDone(robot="lru1", ids=removed)),
            "bad_report",
            "lru1",
            robot="lru1",
        )

    def test_robot_removed_nothing(self, engine, sync, snapshot):
        sync(engine, "lru1")
        plan_unsync(engine)
        before = snapshot(engine)
        applied = engine.submit(UnsyncDone(robot="lru1", ids=[]))
        assert applied.events == []
        assert snapshot(engine) == before

    def test_race_a_skill_started_meanwhile_stays(self, engine, sync, report, ids, skill, inv):
        """plan_unsync of [A, B]; the robot starts A before it gets the
        request, removes only B and says so."""
        c = engine.submit(AddSkill(robot="lru1", skill="recharge")).value["id"]
        sync(engine, "lru1", through="lru1-2")
        assert plan_unsync(engine) == ["lru1-1", "lru1-2"]
        report(engine, "lru1", "lru1-1", Status.RUNNING)
        inv(engine)
        applied = engine.submit(UnsyncDone(robot="lru1", ids=["lru1-2"]))
        engine.release("lru1")
        assert applied.value["unsynchronized"] == ["lru1-2"]
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2", c]
        assert skill(engine, "lru1-1").status == Status.RUNNING
        assert skill(engine, "lru1-2").status == Status.IDLE
        assert skill(engine, c).status == Status.IDLE
        inv(engine)

    def test_race_the_robot_cannot_claim_to_remove_the_started_skill(
        self, engine, sync, report, refused
    ):
        sync(engine, "lru1")
        plan_unsync(engine)
        report(engine, "lru1", "lru1-1", Status.RUNNING)
        refused(
            engine,
            lambda: engine.submit(UnsyncDone(robot="lru1", ids=["lru1-1", "lru1-2"])),
            "bad_report",
            "lru1",
        )

    def test_race_every_skill_started_or_done_meanwhile(self, engine, sync, report, ids, status_of):
        sync(engine, "lru1")
        plan_unsync(engine)
        report(engine, "lru1", "lru1-1", Status.RUNNING)
        report(engine, "lru1", "lru1-1", Status.SUCCESS)
        report(engine, "lru1", "lru1-2", Status.RUNNING)
        engine.submit(UnsyncDone(robot="lru1", ids=[]))
        engine.release("lru1")
        assert [status_of(engine, i) for i in ids(engine, "lru1")] == [
            Status.SUCCESS,
            Status.RUNNING,
        ]
