"""Execution: robot reports, run/pause/stop/reset, retry after a failure."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest

from backend.core.model import Policies, Status
from backend.core.ops import AddSkill, Control, Report, Retry, RetryAck, Sync, Unsync, UnsyncDone

S = Status

# The transition table of the brief / ROSMC: what a robot may report next.
ALLOWED: dict[Status, set[Status]] = {
    S.IDLE: set(),  # leaves idle only through a sync acknowledgement
    S.IDLE_SYNCHRONIZED: {S.SYNCHWAITING, S.RUNNING, S.FAILURE},
    S.SYNCHWAITING: {S.RUNNING, S.IDLE_SYNCHRONIZED, S.FAILURE},
    S.RUNNING: {S.PAUSED, S.SUCCESS, S.FAILURE, S.IDLE_SYNCHRONIZED},
    S.PAUSED: {S.RUNNING, S.IDLE_SYNCHRONIZED, S.FAILURE},
    S.SUCCESS: set(),
    S.FAILURE: set(),
}
FORBIDDEN = [(a, b) for a in Status for b in Status if a != b and b not in ALLOWED[a]]
PERMITTED = [(a, b) for a in Status for b in Status if b in ALLOWED[a]]  # stable order for xdist


def at(minutes: float) -> datetime:
    return datetime(2030, 1, 1, 12, 0, tzinfo=UTC) + timedelta(minutes=minutes)


def control(engine, op, robot="lru1"):
    return engine.plan_control(Control(op=op, robot=robot))


# -- reports: the transition table ----------------------------------------------------


class TestTransitionTable:
    @pytest.mark.parametrize(
        "frm, to", FORBIDDEN, ids=[f"{a.value}->{b.value}" for a, b in FORBIDDEN]
    )
    def test_forbidden_transition_refused(self, engine, bring, report, refused, frm, to):
        bring(engine, "lru1", "lru1-1", frm)
        refused(
            engine,
            lambda: report(engine, "lru1", "lru1-1", to),
            "bad_report",
            "lru1",
            "lru1-1",
            to.value,
            robot="lru1",
            skill="lru1-1",
        )

    @pytest.mark.parametrize(
        "frm, to", PERMITTED, ids=[f"{a.value}->{b.value}" for a, b in PERMITTED]
    )
    def test_permitted_transition_applied(self, engine, bring, report, status_of, frm, to):
        bring(engine, "lru1", "lru1-1", frm)
        rev = engine.mission.revision
        applied = report(engine, "lru1", "lru1-1", to, info="because")
        assert status_of(engine, "lru1-1") == to
        assert applied.revision == rev + 1 == engine.mission.revision

    @pytest.mark.parametrize("finished", [S.SUCCESS, S.FAILURE])
    @pytest.mark.parametrize("to", list(Status))
    def test_finished_skills_are_immutable(self, engine, bring, report, refused, finished, to):
        """success/failure are the execution log: any report on them is
        refused, even one repeating the status with other information."""
        bring(engine, "lru1", "lru1-1", finished)
        refused(
            engine,
            lambda: report(engine, "lru1", "lru1-1", to, info="rewritten", at=at(99)),
            "bad_report",
            "lru1",
            "lru1-1",
            robot="lru1",
            skill="lru1-1",
        )

    def test_report_on_a_skill_of_another_robot_refused(self, engine, sync, report, refused):
        sync(engine, "lru2")
        refused(
            engine,
            lambda: report(engine, "lru1", "lru2-1", S.RUNNING),
            "bad_report",
            "lru1",
            "lru2-1",
            "lru2",
        )

    def test_report_on_an_unknown_skill_refused(self, engine, report, refused):
        """A robot's message the rules refuse is `bad_report`, whatever is
        wrong with it (docs/protocol.md, DownlinkAck.refused)."""
        refused(
            engine,
            lambda: report(engine, "lru1", "nope-1", S.RUNNING),
            "bad_report",
            "nope-1",
            robot="lru1",
            skill="nope-1",
        )

    def test_waiting_at_a_barrier_repeats_with_new_information(self, engine, bring, report, skill):
        bring(engine, "lru1", "lru1-1", S.SYNCHWAITING)
        report(engine, "lru1", "lru1-1", S.SYNCHWAITING, info="waiting for lru2 (offline)")
        assert skill(engine, "lru1-1").status_info == "waiting for lru2 (offline)"
        assert skill(engine, "lru1-1").status == S.SYNCHWAITING

    @pytest.mark.parametrize("status", [S.RUNNING, S.PAUSED, S.IDLE_SYNCHRONIZED])
    def test_the_same_status_at_the_same_attempt_is_refused(
        self, engine, bring, report, refused, status
    ):
        """The table has running -> running only with a higher attempt (an
        autonomous retry); paused or queued never repeat."""
        bring(engine, "lru1", "lru1-1", status)
        r = refused(
            engine,
            lambda: report(engine, "lru1", "lru1-1", status, info="again", attempt=1),
            "bad_report",
            "lru1-1",
            f"{status.value} -> {status.value}",
            robot="lru1",
            skill="lru1-1",
        )
        if status == S.RUNNING:
            assert "same attempt 1" in r.message

    def test_running_again_with_a_higher_attempt_is_a_retry(self, engine, bring, report, skill):
        bring(engine, "lru1", "lru1-1", S.RUNNING)
        report(engine, "lru1", "lru1-1", S.RUNNING, info="retry 1/2", attempt=2)
        assert (skill(engine, "lru1-1").status, skill(engine, "lru1-1").attempt) == (S.RUNNING, 2)


# -- reports: section order -------------------------------------------------------------


class TestSectionOrder:
    @pytest.mark.parametrize("to", [S.RUNNING, S.SYNCHWAITING, S.FAILURE])
    def test_skill_not_first_in_the_queue_cannot_start(self, engine, sync, report, refused, to):
        sync(engine, "lru1")
        refused(
            engine,
            lambda: report(engine, "lru1", "lru1-2", to),
            "bad_report",
            "lru1",
            "lru1-2",
            robot="lru1",
            skill="lru1-2",
        )

    @pytest.mark.parametrize("first", [S.RUNNING, S.PAUSED, S.SYNCHWAITING])
    @pytest.mark.parametrize("to", [S.RUNNING, S.SYNCHWAITING, S.FAILURE])
    def test_second_active_skill_refused(self, engine, sync, bring, report, refused, first, to):
        bring(engine, "lru1", "lru1-1", first)
        sync(engine, "lru1")
        r = refused(
            engine,
            lambda: report(engine, "lru1", "lru1-2", to),
            "bad_report",
            "lru1",
            "lru1-2",
            skill="lru1-2",
        )
        assert "lru1-1" in r.message

    def test_next_skill_starts_after_the_first_finished(self, engine, sync, report, status_of):
        sync(engine, "lru1")
        report(engine, "lru1", "lru1-1", S.RUNNING)
        report(engine, "lru1", "lru1-1", S.SUCCESS)
        report(engine, "lru1", "lru1-2", S.RUNNING)
        assert status_of(engine, "lru1-2") == S.RUNNING

    def test_continue_after_a_failure(self, engine, sync, report, status_of):
        sync(engine, "lru1")
        report(engine, "lru1", "lru1-1", S.RUNNING)
        report(engine, "lru1", "lru1-1", S.FAILURE, info="stuck")
        report(engine, "lru1", "lru1-2", S.RUNNING)
        assert status_of(engine, "lru1-1") == S.FAILURE
        assert status_of(engine, "lru1-2") == S.RUNNING


# -- reports: sequence numbers ---------------------------------------------------------------


class TestSequence:
    def test_same_seq_applied_once(self, engine, sync, snapshot, status_of):
        sync(engine, "lru1")
        rep = Report(robot="lru1", seq=1, id="lru1-1", status=S.RUNNING)
        first = engine.submit(rep)
        assert not first.duplicate
        before = snapshot(engine)
        again = engine.submit(rep)
        assert again.duplicate
        assert again.events == []
        assert snapshot(engine) == before
        assert status_of(engine, "lru1-1") == S.RUNNING

    def test_lower_seq_ignored(self, engine, sync, snapshot, status_of):
        sync(engine, "lru1")
        engine.submit(Report(robot="lru1", seq=5, id="lru1-1", status=S.RUNNING))
        engine.submit(Report(robot="lru1", seq=6, id="lru1-1", status=S.SUCCESS))
        before = snapshot(engine)
        late = engine.submit(Report(robot="lru1", seq=3, id="lru1-1", status=S.PAUSED))
        assert late.duplicate
        assert snapshot(engine) == before
        assert status_of(engine, "lru1-1") == S.SUCCESS

    def test_sequence_numbers_are_per_robot(self, engine, sync, status_of):
        sync(engine, "lru1")
        sync(engine, "lru2")
        engine.submit(Report(robot="lru1", seq=1, id="lru1-1", status=S.RUNNING))
        engine.submit(Report(robot="lru2", seq=1, id="lru2-1", status=S.RUNNING))
        assert status_of(engine, "lru2-1") == S.RUNNING

    def test_gaps_are_fine(self, engine, sync, status_of):
        sync(engine, "lru1")
        engine.submit(Report(robot="lru1", seq=10, id="lru1-1", status=S.RUNNING))
        assert status_of(engine, "lru1-1") == S.RUNNING
        assert engine.mission.report_seqs["lru1"] == 10

    def test_a_refused_report_does_not_use_up_its_seq(self, engine, sync, refused, status_of):
        sync(engine, "lru1")
        refused(
            engine,
            lambda: engine.submit(Report(robot="lru1", seq=1, id="lru1-2", status=S.RUNNING)),
            "bad_report",
        )
        engine.submit(Report(robot="lru1", seq=1, id="lru1-1", status=S.RUNNING))
        assert status_of(engine, "lru1-1") == S.RUNNING


# -- reports: stop, autonomous retry, timestamps --------------------------------------------------


class TestStopRetryTimes:
    @pytest.mark.parametrize("active", [S.RUNNING, S.PAUSED, S.SYNCHWAITING])
    def test_stop_returns_the_active_skill_to_the_queue(
        self, engine, sync, bring, report, skill, ids, active
    ):
        bring(engine, "lru1", "lru1-1", active, at=at(0))
        sync(engine, "lru1")
        report(engine, "lru1", "lru1-1", S.IDLE_SYNCHRONIZED, at=at(3))
        s = skill(engine, "lru1-1")
        assert s.status == S.IDLE_SYNCHRONIZED
        assert s.started_at is None
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2"]
        # the next run starts it from the beginning
        report(engine, "lru1", "lru1-1", S.RUNNING, at=at(5))
        assert skill(engine, "lru1-1").started_at == at(5)

    def test_autonomous_retry_raises_the_attempt(self, engine, bring, report, skill):
        bring(engine, "lru1", "lru1-1", S.RUNNING)
        rev = engine.mission.revision
        report(engine, "lru1", "lru1-1", S.RUNNING, attempt=2, info="retrying after a slip")
        s = skill(engine, "lru1-1")
        assert (s.status, s.attempt) == (S.RUNNING, 2)
        assert engine.mission.revision == rev + 1
        report(engine, "lru1", "lru1-1", S.RUNNING, attempt=3)
        report(engine, "lru1", "lru1-1", S.SUCCESS)
        s = skill(engine, "lru1-1")
        assert (s.status, s.attempt) == (S.SUCCESS, 3)

    def test_timestamps(self, engine, sync, report, skill):
        sync(engine, "lru1")
        report(engine, "lru1", "lru1-1", S.RUNNING, at=at(1))
        assert skill(engine, "lru1-1").started_at == at(1)
        assert skill(engine, "lru1-1").finished_at is None
        report(engine, "lru1", "lru1-1", S.PAUSED, at=at(2))
        report(engine, "lru1", "lru1-1", S.RUNNING, at=at(3))
        assert skill(engine, "lru1-1").started_at == at(1), "resuming keeps the first start"
        report(engine, "lru1", "lru1-1", S.SUCCESS, at=at(4))
        s = skill(engine, "lru1-1")
        assert (s.started_at, s.finished_at) == (at(1), at(4))
        report(engine, "lru1", "lru1-2", S.RUNNING, at=at(5))
        report(engine, "lru1", "lru1-2", S.FAILURE, at=at(6), info="camera fault")
        s = skill(engine, "lru1-2")
        assert (s.started_at, s.finished_at, s.status_info) == (at(5), at(6), "camera fault")


# -- plan_control -------------------------------------------------------------------------------


class TestControl:
    def test_run_a_robot_with_queued_skills(self, engine, sync, snapshot):
        sync(engine, "lru1")
        before = snapshot(engine)["mission"]
        assert control(engine, "run") == ["lru1"]
        assert snapshot(engine)["mission"] == before

    def test_run_with_nothing_to_run_refused(self, engine, refused, bring, report):
        refused(
            engine,
            lambda: control(engine, "run"),
            "not_applicable",
            "lru1",
            "nothing to run",
            robot="lru1",
        )
        # a finished log is nothing to run either
        bring(engine, "lru1", "lru1-1", S.SUCCESS)
        refused(engine, lambda: control(engine, "run"), "not_applicable", "lru1", robot="lru1")

    @pytest.mark.parametrize("active", [S.RUNNING, S.SYNCHWAITING])
    def test_run_while_already_executing_refused(self, engine, bring, sync, refused, active):
        bring(engine, "lru1", "lru1-1", active)
        sync(engine, "lru1")
        refused(
            engine,
            lambda: control(engine, "run"),
            "not_applicable",
            "lru1",
            "already",
            "lru1-1",
            robot="lru1",
        )

    def test_run_on_a_paused_robot_resumes(self, engine, bring):
        bring(engine, "lru1", "lru1-1", S.PAUSED)
        assert control(engine, "run") == ["lru1"]

    def test_pause(self, engine, bring, refused):
        refused(
            engine,
            lambda: control(engine, "pause"),
            "not_applicable",
            "lru1",
            "pause",
            robot="lru1",
        )
        bring(engine, "lru1", "lru1-1", S.RUNNING)
        assert control(engine, "pause") == ["lru1"]

    @pytest.mark.parametrize("status", [S.IDLE_SYNCHRONIZED, S.PAUSED, S.SYNCHWAITING, S.SUCCESS])
    def test_nothing_to_pause_refused(self, engine, bring, refused, status):
        bring(engine, "lru1", "lru1-1", status)
        refused(
            engine,
            lambda: control(engine, "pause"),
            "not_applicable",
            "lru1",
            "pause",
            robot="lru1",
        )

    @pytest.mark.parametrize("active", [S.RUNNING, S.PAUSED, S.SYNCHWAITING])
    def test_stop_an_active_skill(self, engine, bring, active):
        bring(engine, "lru1", "lru1-1", active)
        assert control(engine, "stop") == ["lru1"]

    @pytest.mark.parametrize("status", [S.IDLE, S.IDLE_SYNCHRONIZED, S.SUCCESS, S.FAILURE])
    def test_nothing_to_stop_refused(self, engine, bring, refused, status):
        bring(engine, "lru1", "lru1-1", status)
        refused(
            engine, lambda: control(engine, "stop"), "not_applicable", "lru1", "stop", robot="lru1"
        )

    @pytest.mark.parametrize("status", [S.IDLE_SYNCHRONIZED, S.RUNNING, S.PAUSED, S.SYNCHWAITING])
    def test_reset_claims_the_robot(self, engine, bring, refused, status):
        bring(engine, "lru1", "lru1-1", status)
        assert control(engine, "reset") == ["lru1"]
        refused(
            engine, lambda: engine.plan_sync(Sync(robot="lru1")), "robot_busy", "lru1", robot="lru1"
        )
        refused(engine, lambda: control(engine, "reset"), "robot_busy", "lru1", robot="lru1")
        engine.release("lru1")
        assert [s.id for s in engine.plan_sync(Sync(robot="lru1"))] == ["lru1-2"]

    @pytest.mark.parametrize("status", [S.IDLE, S.SUCCESS, S.FAILURE])
    def test_nothing_to_reset_refused(self, engine, bring, refused, status):
        bring(engine, "lru1", "lru1-1", status)
        refused(
            engine,
            lambda: control(engine, "reset"),
            "not_applicable",
            "lru1",
            "reset",
            robot="lru1",
        )

    def test_reset_flow_stops_and_unsynchronizes_everything_queued(
        self, engine, sync, report, ids, skill
    ):
        sync(engine, "lru1")
        report(engine, "lru1", "lru1-1", S.RUNNING, at=at(1))
        control(engine, "reset")
        report(engine, "lru1", "lru1-1", S.IDLE_SYNCHRONIZED)
        engine.submit(UnsyncDone(robot="lru1", ids=["lru1-1", "lru1-2"]))
        engine.release("lru1")
        assert ids(engine, "lru1") == ["lru1-1", "lru1-2"]
        assert [skill(engine, i).status for i in ids(engine, "lru1")] == [S.IDLE, S.IDLE]
        assert skill(engine, "lru1-1").started_at is None

    def test_all_robots_goes_to_those_it_applies_to(self, engine, sync):
        sync(engine, "lru1")
        assert engine.plan_control(Control(op="run")) == ["lru1"]
        sync(engine, "lru2")
        assert sorted(engine.plan_control(Control(op="run"))) == ["lru1", "lru2"]

    @pytest.mark.parametrize("op", ["run", "pause", "stop", "reset"])
    def test_all_robots_refused_when_it_applies_to_none(self, engine, refused, op):
        refused(
            engine,
            lambda: engine.plan_control(Control(op=op)),
            "not_applicable",
            "lru1",
            "lru2",
            op,
        )

    def test_reset_all_claims_every_robot_it_applies_to(self, engine, sync, refused):
        sync(engine, "lru1")
        sync(engine, "lru2")
        assert sorted(engine.plan_control(Control(op="reset"))) == ["lru1", "lru2"]
        refused(engine, lambda: engine.plan_sync(Sync(robot="lru2")), "robot_busy", "lru2")

    def test_reset_all_refused_while_one_robot_is_busy(self, engine, sync, refused):
        sync(engine, "lru1")
        sync(engine, "lru2", through="lru2-1")
        engine.plan_sync(Sync(robot="lru2"))
        refused(engine, lambda: engine.plan_control(Control(op="reset")), "robot_busy", "lru2")

    def test_unknown_robot_refused(self, engine, refused):
        refused(engine, lambda: control(engine, "run", robot="lru9"), "unknown_robot", "lru9")


# -- retry -----------------------------------------------------------------------------------


def fail_first(engine, sync, report):
    """lru1: [lru1-1 failure, lru1-2 queued]."""
    sync(engine, "lru1")
    report(engine, "lru1", "lru1-1", S.RUNNING, at=at(1))
    report(engine, "lru1", "lru1-1", S.FAILURE, at=at(2), info="wheel stuck")


def retry(engine, sid):
    new = engine.plan_retry(Retry(id=sid))
    robot = engine.mission.find(sid)[0]
    try:
        return new, engine.submit(RetryAck(robot=robot, failed_id=sid, skill=new))
    finally:
        engine.release(robot)


class TestRetry:
    @pytest.mark.parametrize(
        "status", [S.IDLE, S.IDLE_SYNCHRONIZED, S.RUNNING, S.PAUSED, S.SYNCHWAITING, S.SUCCESS]
    )
    def test_only_a_failed_skill_can_be_retried(self, engine, bring, refused, status):
        bring(engine, "lru1", "lru1-1", status)
        refused(
            engine,
            lambda: engine.plan_retry(Retry(id="lru1-1")),
            "cannot_retry",
            "lru1-1",
            "lru1",
            status.value,
            robot="lru1",
            skill="lru1-1",
        )

    def test_unknown_skill_refused(self, engine, refused):
        refused(engine, lambda: engine.plan_retry(Retry(id="nope-1")), "unknown_skill", "nope-1")

    def test_plan_gives_a_new_instance_and_changes_nothing(
        self, engine, sync, report, snapshot, skill
    ):
        fail_first(engine, sync, report)
        before = snapshot(engine)["mission"]
        new = engine.plan_retry(Retry(id="lru1-1"))
        assert snapshot(engine)["mission"] == before
        failed = skill(engine, "lru1-1")
        assert new.id == "lru1-1.2"
        assert new.attempt == 2
        assert new.skill == failed.skill
        assert new.params == failed.params
        assert new.label == failed.label

    def test_ack_places_it_right_after_the_failed_one(self, engine, sync, report, ids, skill):
        fail_first(engine, sync, report)
        failed_before = skill(engine, "lru1-1").model_dump()
        rev = engine.mission.revision
        new, applied = retry(engine, "lru1-1")
        assert applied.revision == rev + 1
        assert applied.value["id"] == "lru1-1.2"
        assert ids(engine, "lru1") == ["lru1-1", "lru1-1.2", "lru1-2"]
        r = skill(engine, "lru1-1.2")
        assert (r.status, r.attempt) == (S.IDLE_SYNCHRONIZED, 2)
        assert r.params == failed_before["params"]
        assert r.bindings == failed_before["bindings"]
        assert r.started_at is None and r.finished_at is None
        # the failed one stays in the log, unchanged
        after = skill(engine, "lru1-1").model_dump()
        assert after["status"] == S.FAILURE
        assert {k: v for k, v in after.items() if k != "rev"} == {
            k: v for k, v in failed_before.items() if k != "rev"
        }

    def test_the_retry_runs_next(self, engine, sync, report, status_of, refused):
        fail_first(engine, sync, report)
        retry(engine, "lru1-1")
        refused(engine, lambda: report(engine, "lru1", "lru1-2", S.RUNNING), "bad_report", "lru1-2")
        report(engine, "lru1", "lru1-1.2", S.RUNNING)
        report(engine, "lru1", "lru1-1.2", S.SUCCESS)
        assert status_of(engine, "lru1-1.2") == S.SUCCESS

    def test_retry_of_a_retry(self, engine, sync, report, ids):
        fail_first(engine, sync, report)
        retry(engine, "lru1-1")
        report(engine, "lru1", "lru1-1.2", S.RUNNING)
        report(engine, "lru1", "lru1-1.2", S.FAILURE)
        new, _ = retry(engine, "lru1-1.2")
        assert (new.id, new.attempt) == ("lru1-1.3", 3)
        assert ids(engine, "lru1") == ["lru1-1", "lru1-1.2", "lru1-1.3", "lru1-2"]

    def test_retry_after_autonomous_retries_counts_on(self, engine, sync, report):
        sync(engine, "lru1")
        report(engine, "lru1", "lru1-1", S.RUNNING)
        report(engine, "lru1", "lru1-1", S.RUNNING, attempt=2)
        report(engine, "lru1", "lru1-1", S.FAILURE)
        new = engine.plan_retry(Retry(id="lru1-1"))
        assert (new.id, new.attempt) == ("lru1-1.3", 3)

    def test_retrying_twice_refused(self, engine, sync, report, refused):
        fail_first(engine, sync, report)
        engine.plan_retry(Retry(id="lru1-1"))
        # while the first retry is in flight
        refused(engine, lambda: engine.plan_retry(Retry(id="lru1-1")), "robot_busy", "lru1")
        engine.release("lru1")
        retry(engine, "lru1-1")
        refused(
            engine,
            lambda: engine.plan_retry(Retry(id="lru1-1")),
            "cannot_retry",
            "lru1-1",
            "lru1-1.2",
            skill="lru1-1",
        )

    def test_retry_while_another_skill_is_active_refused(self, engine, sync, report, refused):
        fail_first(engine, sync, report)
        report(engine, "lru1", "lru1-2", S.RUNNING)
        refused(
            engine,
            lambda: engine.plan_retry(Retry(id="lru1-1")),
            "cannot_retry",
            "lru1-1",
            "lru1-2",
            skill="lru1-1",
        )

    def test_retry_after_later_skills_ran_refused(self, engine, sync, report, refused):
        fail_first(engine, sync, report)
        report(engine, "lru1", "lru1-2", S.RUNNING)
        report(engine, "lru1", "lru1-2", S.SUCCESS)
        refused(
            engine,
            lambda: engine.plan_retry(Retry(id="lru1-1")),
            "cannot_retry",
            "lru1-1",
            skill="lru1-1",
        )

    def test_retry_keeps_the_policies(self, engine, report, sync, skill):
        pol = Policies(retries=2)
        sid = engine.submit(AddSkill(robot="lru2", skill="recharge", policies=pol, at=0)).value[
            "id"
        ]
        sync(engine, "lru2", through=sid)
        report(engine, "lru2", sid, S.RUNNING)
        report(engine, "lru2", sid, S.FAILURE)
        retry(engine, sid)
        assert skill(engine, f"{sid}.2").policies == pol

    def test_bad_retry_ack_refused(self, engine, sync, report, refused):
        fail_first(engine, sync, report)
        new = engine.plan_retry(Retry(id="lru1-1"))
        # not a failed skill
        refused(
            engine,
            lambda: engine.submit(RetryAck(robot="lru1", failed_id="lru1-2", skill=new)),
            "bad_report",
            "lru1-2",
        )
        # not a skill of that robot
        refused(
            engine,
            lambda: engine.submit(RetryAck(robot="lru2", failed_id="lru1-1", skill=new)),
            "bad_report",
            "lru1-1",
        )
        # an id that exists already
        dup = new.model_copy(update={"id": "lru1-2"})
        refused(
            engine,
            lambda: engine.submit(RetryAck(robot="lru1", failed_id="lru1-1", skill=dup)),
            "bad_report",
            "lru1-2",
        )

    def test_unsync_the_rest_after_a_failure(self, engine, sync, report, ids, status_of):
        fail_first(engine, sync, report)
        taken = engine.plan_unsync(Unsync(robot="lru1"))
        assert taken == ["lru1-2"]
        engine.submit(UnsyncDone(robot="lru1", ids=taken))
        engine.release("lru1")
        assert [status_of(engine, i) for i in ids(engine, "lru1")] == [S.FAILURE, S.IDLE]
