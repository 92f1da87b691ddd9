"""A command's verification stages and their dues (backend/core/verification.py)."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

from backend.core.model import (
    CommandState,
    Enqueue,
    Mission,
    Run,
    SkillInstance,
    Status,
    UplinkCommand,
)
from backend.core.ops import Predicted
from backend.core.verification import Path, under_way, verify

T0 = datetime(2026, 11, 28, 12, 0, tzinfo=UTC)
D = 10.0  # one-way delay, s


def at(s: float) -> datetime:
    return T0 + timedelta(seconds=s)


def mission(
    *statuses: Status, started: float | None = None, modes: tuple[UplinkCommand, ...] | None = None
) -> Mission:
    """r1's skills; by default r1 is in run mode (a run it applied before the sync)."""
    skills = [
        SkillInstance(id=f"r1-{i + 1}", skill="drive", status=st) for i, st in enumerate(statuses)
    ]
    if started is not None:
        skills[0] = skills[0].model_copy(update={"started_at": at(started)})
    uplink = list(modes if modes is not None else (mode("run", seq=1, answered=at(-5)),))
    return Mission(library="lib.yaml", tasks={"r1": skills}, uplink={"r1": uplink})


def mode(op: str, seq: int, **kw: object) -> UplinkCommand:
    """A run, pause, stop or reset for r1 (acked when `answered` is given)."""
    state = CommandState.ACKED if "answered" in kw else CommandState.QUEUED
    base: dict[str, object] = {"id": seq, "robot": "r1", "seq": seq, "op": op}
    base |= {"command": {"cmd": op}, "created": T0 - timedelta(seconds=30), "state": state}
    return UplinkCommand.model_validate({**base, **kw})


def sync(**kw: object) -> UplinkCommand:
    base: dict[str, object] = {
        "id": 7,
        "robot": "r1",
        "seq": 2,
        "op": "sync",
        "command": Enqueue(skills=[]),
        "skills": ["r1-1", "r1-2"],
        "created": T0,
    }
    return UplinkCommand.model_validate({**base, **kw})


PLAN = {
    "r1-1": Predicted(start=at(30), end=at(100)),
    "r1-2": Predicted(start=at(100), end=at(200)),
}


def states(v: object) -> dict[str, str]:
    return {s.name: s.state for s in v.stages}  # type: ignore[attr-defined]


def test_dues_follow_the_delay_and_the_forecast() -> None:
    v = verify(sync(), mission(Status.IDLE, Status.IDLE), Path(D), PLAN, at(1))
    dues = {s.name: s.due for s in v.stages}
    assert dues["sent"] == dues["received"] == at(2 * D)  # there and back
    assert dues["started"] == at(30 + D)  # as planned, reported a delay later
    assert dues["completed"] == at(200 + D)
    assert states(v) == {
        "queued": "ok",
        "sent": "waiting",
        "received": "waiting",
        "started": "waiting",
        "completed": "waiting",
    }


def test_a_closed_window_moves_the_dues() -> None:
    opens = at(300)
    path = Path(D, open_from=lambda t: max(t, opens))  # closed until 300 s
    v = verify(sync(), mission(Status.IDLE, Status.IDLE), path, PLAN, at(1))
    assert v.stage("received").due == at(300 + 2 * D)
    # it reaches the robot at 310 s, later than the plan's start: it starts then
    assert v.stage("started").due == at(310 + D)
    assert v.stage("completed").due == at(200 + 280 + D)


def test_no_contact_ahead_or_no_forecast_means_no_due() -> None:
    offline = verify(sync(), mission(Status.IDLE), Path(D, lambda _t: None), PLAN, at(1))
    assert all(s.due is None for s in offline.stages[1:])
    unplanned = verify(sync(), mission(Status.IDLE), Path(D), {}, at(1))
    assert unplanned.stage("received").due is not None
    assert unplanned.stage("started").due is None


def test_a_late_stage_is_overdue_past_its_tolerance() -> None:
    c = sync(state=CommandState.SENT, sent=at(0))
    m = mission(Status.IDLE, Status.IDLE)
    due = at(2 * D)
    tol = verify(c, m, Path(D), PLAN, at(1)).stage("received").tolerance_s
    assert tol >= 2.0
    just = verify(c, m, Path(D), PLAN, due + timedelta(seconds=tol - 0.1))
    assert just.stage("received").state == "waiting"
    late = verify(c, m, Path(D), PLAN, due + timedelta(seconds=tol + 0.1))
    assert late.stage("received").state == "overdue"
    assert late.current is not None and late.current.name == "received"
    graced = verify(c, m, Path(D), PLAN, due + timedelta(seconds=tol + 0.1), grace_s=5)
    assert graced.stage("received").state == "waiting"


def test_acked_is_received_then_running_is_started_then_ended_is_completed() -> None:
    acked = sync(
        state=CommandState.ACKED, sent=at(0), answered=at(20), settled=at(20), done=["r1-1"]
    )
    m = mission(Status.RUNNING, Status.IDLE_SYNCHRONIZED, started=45)
    v = verify(acked, m, Path(D), PLAN, at(60))
    assert v.skills == ["r1-1"]  # what the robot says it queued
    assert states(v)["received"] == "ok" and v.stage("received").at == at(20)
    assert v.stage("started").at == at(45)
    # started 15 s after the plan said: its end moves with it
    assert v.stage("completed").due == at(100 + 15 + D)
    assert under_way(acked, m)
    done = mission(Status.SUCCESS, started=45)
    assert states(verify(acked, done, Path(D), PLAN, at(60)))["completed"] == "ok"
    assert not under_way(acked, done)
    failed = mission(Status.FAILURE, started=45)
    assert states(verify(acked, failed, Path(D), PLAN, at(60)))["completed"] == "failed"


def test_refused_fails_received_and_what_follows() -> None:
    c = sync(state=CommandState.REFUSED, sent=at(0), answered=at(20), settled=at(20))
    v = verify(c, mission(Status.IDLE, Status.IDLE), Path(D), PLAN, at(30))
    assert states(v) == {
        "queued": "ok",
        "sent": "ok",
        "received": "failed",
        "started": "failed",
        "completed": "failed",
    }
    assert v.failed and v.current is None
    assert not under_way(c, mission(Status.IDLE))


def test_a_control_command_has_no_started_or_completed_stage() -> None:
    c = sync(op="run", command=Run(), skills=[])
    v = verify(c, mission(Status.IDLE), Path(D), {}, at(1))
    assert states(v)["started"] == states(v)["completed"] == "none"


def _question(asked: float, due: float, closed: float | None = None) -> object:
    from backend.core.model import Question, QuestionState

    return Question(
        id=1,
        robot="r1",
        ref="q-1",
        skill="r1-1",
        text="search wider?",
        choices=["wider", "give up"],
        default="wider",
        timeout_s=due - asked,
        asked=at(asked),
        due=at(due),
        state=QuestionState.OPEN if closed is None else QuestionState.ANSWERED,
        closed=None if closed is None else at(closed),
    )


def test_a_question_moves_the_end_by_its_wait_not_overdue_meanwhile() -> None:
    acked = sync(
        state=CommandState.ACKED, sent=at(0), answered=at(20), settled=at(20), done=["r1-1"]
    )
    m = mission(Status.RUNNING, Status.IDLE_SYNCHRONIZED, started=30)
    asking = m.model_copy(update={"questions": {"r1": [_question(40, 340)]}})
    # without the question, the end is due at 100 + D; the robot may wait 300 s more
    plain = verify(acked, m, Path(D), PLAN, at(200)).stage("completed")
    assert plain.due == at(100 + D) and plain.state == "overdue"
    v = verify(acked, asking, Path(D), PLAN, at(200)).stage("completed")
    assert v.due == at(100 + 300 + D) and v.state == "waiting"
    # answered after 60 s: only those 60 s count
    answered = m.model_copy(update={"questions": {"r1": [_question(40, 340, closed=100)]}})
    assert verify(acked, answered, Path(D), PLAN, at(200)).stage("completed").due == at(
        100 + 60 + D
    )


def test_dues_count_from_when_the_command_left() -> None:
    """Queued before its robot was heard, it left when the robot registered:
    there and back from then, not from its queuing."""
    late = sync(state=CommandState.SENT, sent=at(600))
    v = verify(late, mission(Status.IDLE, Status.IDLE), Path(D), PLAN, at(601))
    assert v.stage("received").due == at(600 + 2 * D)
    assert v.stage("started").due == at(600 + D + D)  # on the robot at 610, later than planned
    assert states(verify(late, mission(Status.IDLE, Status.IDLE), Path(D), PLAN, at(615))) == {
        "queued": "ok",
        "sent": "ok",
        "received": "waiting",
        "started": "waiting",
        "completed": "waiting",
    }


def test_the_robots_answer_says_when_the_command_reached_it() -> None:
    """`answered` is the robot's own stamp of processing it: on board then, its
    start reported a delay later (not a delay earlier, as for an arrival)."""
    acked = sync(
        state=CommandState.ACKED, sent=at(590), answered=at(600), settled=at(600), done=["r1-1"]
    )
    v = verify(acked, mission(Status.IDLE_SYNCHRONIZED, Status.IDLE), Path(D), PLAN, at(611))
    assert v.stage("started").due == at(600 + D)
    assert v.stage("started").state == "waiting"


def test_a_halted_robot_is_not_late_to_start_until_a_run_is_on_its_way() -> None:
    """Synchronized without a run, the skills wait for the operator, not the
    robot: no start or end is due (the demo said 'has not started … 27 s late')."""
    halted = mission(Status.IDLE_SYNCHRONIZED, Status.IDLE_SYNCHRONIZED, modes=())
    v = verify(
        sync(sent=T0, state=CommandState.ACKED, answered=at(D), done=["r1-1", "r1-2"]),
        halted,
        Path(D),
        PLAN,
        at(500),
    )
    assert v.stage("started").due is None and v.stage("completed").due is None
    assert states(v)["started"] == "waiting"  # not overdue
    ran = mode("run", seq=1, answered=at(-9))
    stopped = mission(Status.IDLE_SYNCHRONIZED, modes=(ran, mode("stop", seq=2, answered=at(-5))))
    v = verify(sync(seq=3), stopped, Path(D), PLAN, at(500))
    assert v.stage("started").due is None


def test_a_run_sent_after_the_sync_times_the_start_from_its_arrival() -> None:
    run = mode("run", seq=3, created=at(100), sent=at(100))
    later = mission(Status.IDLE_SYNCHRONIZED, Status.IDLE_SYNCHRONIZED, modes=(run,))
    v = verify(sync(sent=T0), later, Path(D), PLAN, at(101))
    assert v.stage("started").due == at(100 + 2 * D)  # the run arrives, word comes back
    assert v.stage("completed").due == at(200 + 70 + 2 * D)  # the plan, 70 s later than it said
    cancelled = run.model_copy(update={"state": CommandState.CANCELLED})
    v = verify(
        sync(sent=T0), mission(Status.IDLE_SYNCHRONIZED, modes=(cancelled,)), Path(D), PLAN, at(101)
    )
    assert v.stage("started").due is None  # a run that never goes does not count
