"""The uplink as rules: an operation on a robot queues a command and returns;
the robot's answer (what it actually did) is what the mission then shows;
cancel, expiry, the race of a command the ground gave up on, and a robot's
registration reconciled both ways. No transport: the robot is played here."""

from __future__ import annotations

from datetime import timedelta

import pytest

from backend.core.model import CommandState, Status
from backend.core.ops import (
    AddSkill,
    Answer,
    Cancel,
    Control,
    DeleteSkills,
    EditSkill,
    MoveSkill,
    QueueEntry,
    Reconcile,
    Retry,
    Sync,
    Undo,
    Unsync,
    UplinkSent,
    UplinkSettle,
)
from backend.core.rules.engine import Refusal

from .conftest import T0


def answer(engine, robot, command, outcome="applied", **kw):
    """The robot's answer to its command number `command` (uplink seq), as
    the next message of its downlink."""
    seq = engine.mission.report_seqs.get(robot, 0) + 1
    return engine.submit(
        Answer(robot=robot, seq=seq, command=command, outcome=outcome, at=T0, **kw)
    )


def cmd(engine, cid):
    c = engine.mission.command(cid)
    assert c is not None
    return c


@pytest.fixture(autouse=True)
def _clock(engine):
    engine.clock = lambda: T0


class TestQueueing:
    def test_sync_returns_at_once_with_the_skills_uplinking(self, engine, ids, status_of):
        applied = engine.submit(Sync(robot="lru1", through="lru1-1", expire_s=60), client="c")
        v = applied.value
        assert (v["command"], v["robot"], v["seq"], v["state"]) == (1, "lru1", 1, "queued")
        assert v["skills"] == ["lru1-1"]
        c = cmd(engine, 1)
        assert c.op == "sync" and c.expires == T0 + timedelta(seconds=60)
        assert [s.id for s in c.command.skills] == ["lru1-1"]
        assert c.command.skills[0].params["goal"]["x"] == 10.0  # bound values taken fresh
        assert status_of(engine, "lru1-1") == Status.IDLE  # not on the robot yet
        assert "command 1" in engine.locked["lru1-1"]

    def test_uplinking_skills_are_locked(self, engine, refused):
        engine.submit(Sync(robot="lru1", through="lru1-1"))
        refused(engine, lambda: engine.submit(EditSkill(id="lru1-1", label="x")), "locked", "1")
        refused(engine, lambda: engine.submit(DeleteSkills(ids=["lru1-1"])), "locked")
        refused(engine, lambda: engine.submit(MoveSkill(id="lru1-2", index=0)), "locked")
        refused(
            engine,
            lambda: engine.submit(AddSkill(robot="lru1", skill="recharge", at=0)),
            "locked",
        )

    def test_a_second_sync_goes_on_after_the_uplinking_skills(self, engine):
        engine.submit(Sync(robot="lru1", through="lru1-1"))
        second = engine.submit(Sync(robot="lru1"))
        assert second.value["skills"] == ["lru1-2"] and second.value["seq"] == 2
        with pytest.raises(Refusal) as r:
            engine.submit(Sync(robot="lru1"))
        assert r.value.code == "nothing_to_sync" and "being synchronized" in r.value.message

    def test_run_on_a_robot_with_a_pending_sync_is_queued_behind_it(self, engine):
        engine.submit(Sync(robot="lru1"))
        run = engine.submit(Control(op="run", robot="lru1"))
        assert run.value["commands"] == {"lru1": 2}
        assert cmd(engine, 2).seq == 2

    def test_run_for_all_robots_numbers_each_robots_uplink(self, engine, sync):
        sync(engine, "lru1")
        sync(engine, "lru2")
        applied = engine.submit(Control(op="run"))
        assert applied.value["commands"] == {"lru1": 1, "lru2": 2}
        assert [cmd(engine, 1).seq, cmd(engine, 2).seq] == [1, 1]

    def test_nothing_to_pause_is_refused_unless_a_run_is_pending(self, engine, sync, refused):
        sync(engine, "lru1")
        refused(engine, lambda: engine.submit(Control(op="pause", robot="lru1")), "not_applicable")
        engine.submit(Control(op="run", robot="lru1"))
        assert engine.submit(Control(op="pause", robot="lru1")).value["commands"] == {"lru1": 2}


class TestAnswers:
    def test_the_ids_the_robot_queued_become_synchronized_the_others_idle(
        self, engine, ids, status_of
    ):
        engine.submit(Sync(robot="lru1"))
        applied = answer(engine, "lru1", 1, queued=["lru1-2"], reason="no room for lru1-1")
        assert status_of(engine, "lru1-2") == Status.IDLE_SYNCHRONIZED
        assert status_of(engine, "lru1-1") == Status.IDLE  # the robot does not hold it
        assert ids(engine, "lru1") == ["lru1-2", "lru1-1"]  # section order: queued first
        c = cmd(engine, 1)
        assert c.state == CommandState.ACKED and c.done == ["lru1-2"]
        assert "lru1-1" not in engine.locked
        [alert] = applied.alerts
        assert "lru1 did not queue lru1-1" in alert.message and alert.robot == "lru1"
        assert "no room" in alert.message

    def test_an_answer_naming_a_skill_it_was_not_sent_is_ignored(self, engine, status_of):
        engine.submit(Sync(robot="lru1", through="lru1-1"))
        applied = answer(engine, "lru1", 1, queued=["lru1-1", "lru1-2", "lru2-1"])
        assert status_of(engine, "lru1-2") == Status.IDLE
        assert status_of(engine, "lru2-1") == Status.IDLE
        assert len([a for a in applied.alerts if "did not send" in a.message]) == 2

    def test_a_refusal_returns_the_skills_with_an_alert(self, engine, status_of):
        engine.submit(Sync(robot="lru1"))
        applied = answer(engine, "lru1", 1, "refused", reason="no handler for drive_to")
        assert cmd(engine, 1).state == CommandState.REFUSED
        assert status_of(engine, "lru1-1") == Status.IDLE and engine.locked == {}
        [alert] = applied.alerts
        assert "command 1" in alert.message and "no handler" in alert.message

    def test_the_same_answer_twice_is_applied_once(self, engine):
        engine.submit(Sync(robot="lru1"))
        first = answer(engine, "lru1", 1, queued=["lru1-1", "lru1-2"])
        again = engine.submit(
            Answer(robot="lru1", seq=1, command=1, outcome="applied", queued=["lru1-1"])
        )
        assert again.duplicate and not first.duplicate
        late = answer(engine, "lru1", 1, queued=[])  # a new number: answered already
        assert "answered already" in late.alerts[0].message

    def test_unsync_race_the_started_skill_stays(self, engine, sync, report, ids, status_of):
        sync(engine, "lru1")
        engine.submit(Unsync(robot="lru1"))  # lru1-1, lru1-2
        report(engine, "lru1", "lru1-1", "running")  # started before the dequeue arrived
        applied = answer(engine, "lru1", 1, removed=["lru1-2"], kept=["lru1-1"])
        assert status_of(engine, "lru1-1") == Status.RUNNING
        assert status_of(engine, "lru1-2") == Status.IDLE
        assert cmd(engine, 1).kept == ["lru1-1"]
        assert any("already started lru1-1" in n for n in applied.notes)

    def test_reset_returns_what_the_robot_removed(self, engine, sync, report, ids, status_of):
        sync(engine, "lru1")
        report(engine, "lru1", "lru1-1", "running")
        engine.submit(Control(op="reset", robot="lru1"))
        answer(engine, "lru1", 1, removed=["lru1-1", "lru1-2"])
        assert [status_of(engine, s) for s in ("lru1-1", "lru1-2")] == [Status.IDLE] * 2
        assert engine.mission.find("lru1-1")[2].started_at is None

    def test_retry_joins_the_mission_when_the_robot_has_it(self, engine, sync, report, ids):
        sync(engine, "lru1")
        report(engine, "lru1", "lru1-1", "running")
        report(engine, "lru1", "lru1-1", "failure")
        v = engine.submit(Retry(id="lru1-1")).value
        assert v["id"] == "lru1-1.2" and "lru1-1.2" not in ids(engine, "lru1")
        with pytest.raises(Refusal) as r:
            engine.submit(Retry(id="lru1-1"))
        assert r.value.code == "cannot_retry" and "being retried" in r.value.message
        answer(engine, "lru1", v["seq"], queued=["lru1-1.2"])
        assert ids(engine, "lru1") == ["lru1-1", "lru1-1.2", "lru1-2"]


class TestWithdrawing:
    def test_cancel_of_a_queued_command_is_final(self, engine, status_of):
        engine.submit(Sync(robot="lru1"))
        v = engine.submit(Cancel(command=1)).value
        assert v["state"] == "cancelled" and cmd(engine, 1).state == CommandState.CANCELLED
        assert engine.locked == {}
        engine.submit(EditSkill(id="lru1-1", label="editable again"))

    def test_cancel_of_a_sent_command_is_a_request(self, engine):
        engine.submit(Sync(robot="lru1"))
        engine.submit(UplinkSent(robot="lru1", ids=[1], at=T0))
        applied = engine.submit(Cancel(command=1))
        c = cmd(engine, 1)
        assert c.state == CommandState.SENT and c.cancel_requested
        assert applied.value["cancel_requested"] and "its answer says which" in applied.notes[0]
        answer(engine, "lru1", 1, "cancelled")
        assert cmd(engine, 1).state == CommandState.CANCELLED

    def test_a_command_being_transmitted_cannot_be_cancelled_at_once(self, engine):
        engine.submit(Sync(robot="lru1"))
        engine.transmitting.add(1)
        engine.submit(Cancel(command=1))
        assert cmd(engine, 1).state == CommandState.QUEUED and cmd(engine, 1).cancel_requested

    def test_undo_of_a_queued_sync_cancels_it(self, engine):
        engine.submit(AddSkill(robot="lru1", skill="recharge"), client="c")
        engine.submit(Sync(robot="lru1"), client="c")
        engine.submit(Undo(), client="c")
        assert cmd(engine, 1).state == CommandState.CANCELLED

    def test_undo_of_a_sent_sync_is_refused(self, engine):
        engine.submit(Sync(robot="lru1"), client="c")
        engine.submit(UplinkSent(robot="lru1", ids=[1], at=T0))
        with pytest.raises(Refusal) as r:
            engine.submit(Undo(), client="c")
        assert "may be on lru1" in r.value.message and "ctl cancel 1" in r.value.message

    def test_expiry_before_sending_releases_the_skills(self, engine, status_of):
        engine.submit(Sync(robot="lru1", expire_s=5))
        applied = engine.submit(
            UplinkSettle(robot="lru1", ids=[1], state="expired", reason="expired unsent", at=T0)
        )
        assert cmd(engine, 1).state == CommandState.EXPIRED and engine.locked == {}
        assert "lru1-1, lru1-2 are unsynchronized" in applied.alerts[0].message

    def test_a_robot_that_applied_a_cancelled_sync_is_believed(self, engine, status_of):
        engine.submit(Sync(robot="lru1"))
        engine.submit(Cancel(command=1))
        engine.submit(EditSkill(id="lru1-2", label="changed since"))
        applied = answer(engine, "lru1", 1, queued=["lru1-1", "lru1-2"])
        assert status_of(engine, "lru1-1") == Status.IDLE_SYNCHRONIZED  # untouched: adopted
        assert status_of(engine, "lru1-2") == Status.IDLE  # edited: asked back
        drop = cmd(engine, 2)
        assert drop.op == "reconcile" and drop.command.ids == ["lru1-2"]
        messages = " ".join(a.message for a in applied.alerts)
        assert "after the ground had given up" in messages and "command 2" in messages


class TestReconcile:
    def test_lost_skills_return_adopted_ones_are_queued_strays_asked_back(
        self, engine, sync, ids, status_of
    ):
        sync(engine, "lru1", through="lru1-1")
        queue = [
            QueueEntry(id="lru1-2", status=Status.IDLE_SYNCHRONIZED),
            QueueEntry(id="ghost-9", status=Status.IDLE_SYNCHRONIZED),
        ]
        applied = engine.submit(Reconcile(robot="lru1", queue=queue))
        v = applied.value
        assert v["unsynchronized"] == ["lru1-1"] and v["adopted"] == ["lru1-2"]
        assert v["dropped"] == ["ghost-9"]
        assert status_of(engine, "lru1-2") == Status.IDLE_SYNCHRONIZED
        assert status_of(engine, "lru1-1") == Status.IDLE
        assert ids(engine, "lru1") == ["lru1-2", "lru1-1"]
        assert engine.mission.pending_commands("lru1")[0].command.ids == ["ghost-9"]
        assert len(applied.alerts) == 3

    def test_a_skill_being_synchronized_is_left_to_its_answer(self, engine, status_of):
        engine.submit(Sync(robot="lru1"))
        queue = [QueueEntry(id="lru1-1", status=Status.IDLE_SYNCHRONIZED)]
        applied = engine.submit(Reconcile(robot="lru1", queue=queue))
        assert applied.value["adopted"] == [] and status_of(engine, "lru1-1") == Status.IDLE

    def test_the_robots_status_and_order_win(self, engine, sync, ids, status_of):
        sync(engine, "lru1")
        queue = [
            QueueEntry(id="lru1-2", status=Status.RUNNING),
            QueueEntry(id="lru1-1", status=Status.IDLE_SYNCHRONIZED),
        ]
        engine.submit(Reconcile(robot="lru1", queue=queue))
        assert ids(engine, "lru1") == ["lru1-2", "lru1-1"]
        assert status_of(engine, "lru1-2") == Status.RUNNING

    def test_a_copy_with_other_parameters_is_not_adopted(self, engine, status_of):
        q = [QueueEntry(id="lru1-1", status="idle_synchronized", skill="drive_to", params={})]
        v = engine.submit(Reconcile(robot="lru1", queue=q)).value
        assert v["dropped"] == ["lru1-1"] and status_of(engine, "lru1-1") == Status.IDLE
