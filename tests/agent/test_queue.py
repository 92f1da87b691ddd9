"""The robot's queue as a state machine (`backend.agent.queue.SkillQueue`):
plain calls, no router, no event loop.

Every queue made by the `queue` fixture is checked after the test: its
reports are numbered one after the other in the order made, no skill is held
twice, and no finished skill is held.
"""

from __future__ import annotations

from collections.abc import Iterator
from datetime import UTC, datetime
from typing import Any

import pytest

from backend.agent.queue import Effect, SkillQueue
from backend.core.model import Policies, SkillInstance, Status
from backend.core.ops import Report
from backend.protocol.messages import BarrierInfo

S = Status
T0 = datetime(2030, 1, 1, 12, 0, tzinfo=UTC)
OFFERED = {"work", "drive", "recharge"}


class Recorded(SkillQueue):
    """A queue that keeps the reports it made (`made`) and what it finished."""

    def __init__(self) -> None:
        self.made: list[Report] = []
        self.finished: set[str] = set()
        super().__init__("lru1", on_report=self.made.append, clock=lambda: T0)

    def finish(self, status: Status, info: str = "") -> Report:
        assert self.active is not None
        self.finished.add(self.active.entry.id)
        return super().finish(status, info)

    def trail(self) -> list[tuple[str, str, str]]:
        """(id, status, info) of every report, in order."""
        return [(r.id, r.status.value, r.info) for r in self.made]

    def start(self) -> str:
        """Run mode, the head becomes active and reports running; its id."""
        self.run()
        active = self.next_skill()
        assert active is not None
        self.report(active.entry, S.RUNNING)
        return active.entry.id


@pytest.fixture
def queue() -> Iterator[Recorded]:
    q = Recorded()
    yield q
    seqs = [r.seq for r in q.made]
    assert all(b == a + 1 for a, b in zip(seqs, seqs[1:], strict=False)), seqs
    assert q.seq == (seqs[-1] if seqs else 0)
    held = [e.id for e in q.entries()]
    assert len(held) == len(set(held)), f"held twice: {held}"
    assert not q.finished & set(held), "a finished skill is held"


def inst(sid: str, name: str = "work", *, attempt: int = 1, retries: int = 0) -> SkillInstance:
    return SkillInstance(
        id=sid, skill=name, status=S.IDLE, attempt=attempt, policies=Policies(retries=retries)
    )


def enqueue(queue: SkillQueue, *ids: str, **kw: Any) -> Effect:
    return queue.enqueue([inst(i) for i in ids], offered=OFFERED, **kw)


# -- enqueue ----------------------------------------------------------------------------


class TestEnqueue:
    def test_queues_in_order_and_says_what_it_queued(self, queue):
        change = enqueue(queue, "a", "b")
        assert change == Effect(queued=["a", "b"])
        assert enqueue(queue, "c").queued == ["c"]
        assert queue.waiting == ["a", "b", "c"]
        assert [e.status for e in queue.entries()] == [S.IDLE_SYNCHRONIZED] * 3
        assert queue.made == []  # queuing is not a status change of the robot

    def test_front_goes_first(self, queue):
        enqueue(queue, "a", "b")
        assert enqueue(queue, "c", "d", front=True).queued == ["c", "d"]
        assert queue.waiting == ["c", "d", "a", "b"]

    def test_a_retry_the_operator_asked_for_goes_to_the_head_with_its_attempt(self, queue):
        enqueue(queue, "a", "b")
        queue.enqueue([inst("a-r2", attempt=2)], front=True, offered=OFFERED)
        assert queue.waiting == ["a-r2", "a", "b"]
        assert queue.holds("a-r2").attempt == 2

    def test_sent_again_it_changes_nothing_and_answers_the_same(self, queue):
        first = enqueue(queue, "a", "b")
        again = enqueue(queue, "a", "b")
        assert again == first
        assert queue.waiting == ["a", "b"]

    def test_sent_again_after_a_start_the_active_skill_is_not_queued_twice(self, queue):
        enqueue(queue, "a", "b")
        queue.start()
        assert enqueue(queue, "a", "b").queued == ["a", "b"]
        assert queue.waiting == ["b"]
        assert queue.active.entry.id == "a"

    def test_a_finished_skill_is_never_queued_again(self, queue):
        enqueue(queue, "a")
        queue.start()
        queue.finish(S.SUCCESS)
        assert enqueue(queue, "a", "b").queued == ["b"]
        assert queue.waiting == ["b"]

    def test_one_id_twice_in_one_command_is_queued_once(self, queue):
        assert enqueue(queue, "a", "a").queued == ["a", "a"]
        assert queue.waiting == ["a"]

    def test_a_skill_without_handler_refuses_the_whole_command(self, queue):
        change = queue.enqueue([inst("a"), inst("b", "fly"), inst("c", "dig")], offered={"work"})
        assert not change.ok
        assert change.reason == "lru1 has no handler for skill dig, fly (it offers: work)"
        assert queue.waiting == []
        assert "(it offers: none)" in queue.enqueue([inst("a")], offered=()).reason

    def test_barrier_info_and_a_fresh_status_travel_with_the_entry(self, queue):
        info = BarrierInfo(barrier="b1", partners={"lru1": "a", "lru2": "x"})
        s = inst("a").model_copy(update={"status": S.FAILURE, "attempt": 3})
        queue.enqueue([s, inst("b")], {"a": info}, offered=OFFERED)
        a, b = queue.entries()
        assert (a.barrier, a.attempt, a.skill.status) == (info, 3, S.IDLE_SYNCHRONIZED)
        assert b.barrier is None


# -- run mode and the next skill ----------------------------------------------------------


class TestNextSkill:
    def test_halted_until_run(self, queue):
        enqueue(queue, "a")
        assert queue.mode == "halted"
        assert queue.next_skill() is None
        assert queue.run() == Effect()
        assert queue.mode == "running"
        assert queue.next_skill().entry.id == "a"
        assert queue.mode == "starting"  # active, not reported yet

    def test_one_at_a_time_head_first(self, queue):
        enqueue(queue, "a", "b")
        queue.run()
        assert queue.next_skill().entry.id == "a"
        assert queue.next_skill() is None  # a is active
        queue.report(queue.active.entry, S.RUNNING)
        assert queue.mode == "running"
        queue.finish(S.SUCCESS)
        assert queue.next_skill().entry.id == "b"

    def test_run_mode_stays_on_when_the_queue_drains(self, queue):
        assert queue.mode == "idle"
        change = queue.run()
        assert change.ok
        assert change.reason == "lru1 has nothing queued; it will run what is synchronized next"
        assert queue.run_enabled
        enqueue(queue, "a")
        assert queue.next_skill().entry.id == "a"

    def test_a_failure_leaves_run_mode_a_success_does_not(self, queue):
        enqueue(queue, "a", "b", "c")
        queue.start()
        queue.finish(S.SUCCESS, "found a stone")
        assert queue.run_enabled
        assert queue.next_skill().entry.id == "b"
        queue.finish(S.FAILURE, "stuck")
        assert not queue.run_enabled
        assert queue.next_skill() is None
        assert queue.trail() == [
            ("a", "running", ""),
            ("a", "success", "found a stone"),
            ("b", "failure", "stuck"),
        ]

    def test_the_queue_is_the_active_skill_then_the_waiting_ones(self, queue):
        enqueue(queue, "a", "b")
        queue.start()
        assert [(e.id, e.status) for e in queue.entries()] == [
            ("a", S.RUNNING),
            ("b", S.IDLE_SYNCHRONIZED),
        ]
        assert queue.waiting == ["b"]


# -- unsync --------------------------------------------------------------------------------


class TestUnsync:
    def test_removes_what_has_not_started(self, queue):
        enqueue(queue, "a", "b", "c")
        assert queue.unsync(["c", "a"]) == Effect(removed=["a", "c"])
        assert queue.waiting == ["b"]

    def test_what_started_meanwhile_stays_and_is_said(self, queue):
        enqueue(queue, "a", "b", "c")
        queue.start()
        queue.finish(S.SUCCESS)
        queue.next_skill()  # b is active now
        change = queue.unsync(["a", "b", "c"])
        assert change == Effect(removed=["c"], started=["a", "b"])
        assert queue.active.entry.id == "b"
        assert queue.waiting == []

    def test_ids_it_never_had_count_as_removed(self, queue):
        enqueue(queue, "a")
        assert queue.unsync(["x", "a"]) == Effect(removed=["a", "x"])


# -- pause and run ---------------------------------------------------------------------------


class TestPauseAndRun:
    def test_pause_a_running_skill_then_run_resumes_it(self, queue):
        enqueue(queue, "a")
        queue.start()
        assert queue.pause() == Effect()
        assert not queue.run_enabled
        assert queue.active.paused_by_operator and queue.mode == "paused"
        assert queue.pause() == Effect()  # paused already: no second report
        assert queue.run() == Effect()
        assert not queue.active.paused
        assert queue.trail() == [
            ("a", "running", ""),
            ("a", "paused", "paused by operator"),
            ("a", "running", "resumed"),
        ]

    def test_a_skill_not_running_yet_is_held_without_a_report(self, queue):
        enqueue(queue, "a")
        queue.run()
        queue.next_skill()
        queue.pause()
        assert queue.active.paused
        assert queue.made == []

    def test_a_skill_waiting_at_a_barrier_cannot_be_paused(self, queue):
        enqueue(queue, "a")
        queue.run()
        queue.report(queue.next_skill().entry, S.SYNCHWAITING, "waiting for lru2")
        change = queue.pause()
        assert not change.ok
        assert change.reason == (
            "lru1 is waiting at a barrier with a; only a running skill can be paused "
            "(stop it instead)"
        )
        assert queue.run_enabled  # refused: nothing changed
        assert not queue.active.paused

    def test_pause_with_nothing_active_halts_the_queue(self, queue):
        enqueue(queue, "a")
        queue.run()
        change = queue.pause()
        assert change == Effect(reason="lru1 has no running skill; its queue is halted")
        assert queue.mode == "halted"


# -- stop and reset ---------------------------------------------------------------------------


class TestStopAndReset:
    def test_stop_puts_the_skill_back_at_the_head(self, queue):
        enqueue(queue, "a", "b")
        queue.start()
        assert queue.stop() == Effect()
        assert queue.active is None and not queue.run_enabled
        assert queue.waiting == ["a", "b"]
        assert queue.made[-1].status == S.IDLE_SYNCHRONIZED
        assert queue.made[-1].info == "stopped by operator"
        queue.run()
        again = queue.next_skill()
        assert again.entry.id == "a" and not again.paused  # afresh

    def test_stop_of_a_paused_skill_forgets_the_pause(self, queue):
        enqueue(queue, "a")
        queue.start()
        queue.pause()
        queue.stop()
        queue.run()
        assert not queue.next_skill().paused

    def test_stop_before_the_first_report_makes_none(self, queue):
        enqueue(queue, "a")
        queue.run()
        queue.next_skill()
        queue.stop()
        assert queue.made == []
        assert queue.waiting == ["a"]

    def test_stop_with_nothing_active(self, queue):
        enqueue(queue, "a")
        queue.run()
        change = queue.stop()
        assert change == Effect(reason="lru1 has no active skill; its queue is halted")
        assert not queue.run_enabled

    def test_reset_forgets_everything(self, queue):
        enqueue(queue, "a", "b", "c")
        queue.start()
        assert queue.reset() == Effect(removed=["a", "b", "c"])
        assert queue.entries() == [] and not queue.run_enabled
        assert queue.trail()[-1] == ("a", "idle_synchronized", "reset by operator")
        # forgotten, not finished: it may be synchronized again
        assert enqueue(queue, "a").queued == ["a"]

    def test_abandon_drops_the_active_skill_without_a_report(self, queue):
        enqueue(queue, "a", "b")
        queue.start()
        queue.abandon()
        assert queue.active is None and queue.waiting == ["b"]
        assert len(queue.made) == 1


# -- policies: retries and the communication range -------------------------------------------


class TestRetries:
    def test_each_retry_is_the_next_attempt_until_none_is_left(self, queue):
        queue.enqueue([inst("a", retries=2)], offered=OFFERED)
        queue.start()
        assert queue.next_attempt()
        assert queue.next_attempt()
        assert not queue.next_attempt()
        entry = queue.active.entry
        assert (entry.attempt, entry.retries_used, entry.skill.attempt) == (3, 2, 3)
        assert queue.finish(S.FAILURE, "stuck").attempt == 3

    def test_no_retries_no_next_attempt(self, queue):
        enqueue(queue, "a")
        queue.start()
        assert not queue.next_attempt()
        assert queue.active.entry.attempt == 1


class TestCommsPause:
    def test_out_of_range_pauses_back_in_range_resumes(self, queue):
        enqueue(queue, "a")
        queue.start()
        assert queue.pause_for_comms()
        assert not queue.pause_for_comms()  # paused for it already
        assert queue.resume_after_comms()
        assert not queue.resume_after_comms()
        assert queue.trail()[1:] == [
            ("a", "paused", "paused: out of communication range"),
            ("a", "running", "resumed: back in communication range"),
        ]

    def test_an_operator_pause_outlasts_the_comms_pause(self, queue):
        enqueue(queue, "a")
        queue.start()
        queue.pause()
        assert queue.pause_for_comms()  # paused already: no report
        assert queue.resume_after_comms()  # still paused by the operator: no report
        assert queue.active.paused
        queue.run()
        assert [s for _, s, _ in queue.trail()] == ["running", "paused", "running"]

    def test_only_a_running_or_paused_skill_pauses_for_comms(self, queue):
        assert not queue.pause_for_comms()  # nothing active
        enqueue(queue, "a")
        queue.run()
        queue.report(queue.next_skill().entry, S.SYNCHWAITING)
        assert not queue.pause_for_comms()
        assert not queue.active.paused


# -- report numbering ---------------------------------------------------------------------------


class TestNumbering:
    def test_reports_are_numbered_from_one(self, queue):
        enqueue(queue, "a")
        queue.start()
        r = queue.finish(S.SUCCESS, "done")
        assert [x.seq for x in queue.made] == [1, 2]
        assert r == Report(
            robot="lru1", seq=2, id="a", status=S.SUCCESS, info="done", attempt=1, at=T0
        )

    def test_after_a_higher_server_number_pending_reports_are_renumbered(self, queue):
        enqueue(queue, "a")
        queue.start()
        queue.pause()
        pending = list(queue.made)
        renumbered = queue.continue_after(40, pending)
        assert [r.seq for r in renumbered] == [41, 42]
        assert [(r.id, r.status) for r in renumbered] == [(r.id, r.status) for r in pending]
        assert queue.seq == 42
        queue.run()
        assert queue.made[-1].seq == 43
        queue.made[:] = renumbered + queue.made[2:]  # as the outbox now holds them

    def test_a_lower_server_number_changes_nothing(self, queue):
        enqueue(queue, "a")
        queue.start()
        assert queue.continue_after(1, list(queue.made)) is None
        assert queue.continue_after(0, []) is None
        assert queue.seq == 1
