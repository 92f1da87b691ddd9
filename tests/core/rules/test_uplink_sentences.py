"""The uplink's sentences, word for word: what a robot's answer, its
registration and a refused command say to an operator (alerts, notes,
refusals). Pinned so that reshaping the rules (issue 27) keeps them."""

from __future__ import annotations

import pytest

from backend.core.ops import Answer, Cancel, Control, QueueEntry, Reconcile, Retry, Sync, Unsync
from backend.core.rules.engine import Refusal

from .conftest import T0


def answer(engine, robot, command, outcome="applied", **kw):
    seq = engine.mission.report_seqs.get(robot, 0) + 1
    return engine.submit(
        Answer(robot=robot, seq=seq, command=command, outcome=outcome, at=T0, **kw)
    )


def said(applied) -> list[tuple[str, str]]:
    return [(a.level, a.message) for a in applied.alerts]


def refusal(call) -> dict[str, str]:
    with pytest.raises(Refusal) as r:
        call()
    return r.value.to_dict()


@pytest.fixture(autouse=True)
def _clock(engine):
    engine.clock = lambda: T0


def test_an_id_the_sync_did_not_send_is_ignored(engine):
    engine.submit(Sync(robot="lru1", through="lru1-1"))
    applied = answer(engine, "lru1", 1, queued=["lru1-1", "lru2-1"])
    assert said(applied) == [
        (
            "error",
            "lru1 says it queued lru2-1, which command 1 (sync lru1-1) did not send: ignored",
        )
    ]


def test_skills_the_robot_did_not_queue_say_why(engine):
    engine.submit(Sync(robot="lru1"))
    applied = answer(engine, "lru1", 1, queued=["lru1-2"], reason="no room")
    assert said(applied) == [
        (
            "warning",
            "lru1 did not queue lru1-1 (command 1 (sync lru1-1, lru1-2)): no room; "
            "they are unsynchronized (idle) again",
        )
    ]


def test_removals_not_asked_for_are_ignored(engine, sync, report):
    sync(engine, "lru1")
    report(engine, "lru1", "lru1-1", "running")
    report(engine, "lru1", "lru1-1", "success")
    engine.submit(Unsync(robot="lru1"))
    applied = answer(engine, "lru1", 1, removed=["lru2-1", "lru1-1", "lru1-2"])
    assert said(applied) == [
        (
            "error",
            "lru1 says it removed lru2-1, which command 1 (unsync lru1-2) did not ask for: ignored",
        ),
        (
            "error",
            "lru1 says it removed lru1-1, which command 1 (unsync lru1-2) did not ask for: ignored",
        ),
    ]


def test_a_finished_skill_a_reset_removed_stays_in_the_log(engine, sync, report):
    sync(engine, "lru1")
    report(engine, "lru1", "lru1-1", "running")
    report(engine, "lru1", "lru1-1", "success")
    engine.submit(Control(op="reset", robot="lru1"))
    applied = answer(engine, "lru1", 1, removed=["lru1-1", "lru1-2"])
    assert said(applied) == [
        ("error", "lru1 says it removed lru1-1, which it had finished (success): the log stays")
    ]
    assert applied.value == {"command": 1, "state": "acked"}


def test_a_started_skill_an_unsync_kept_is_a_note(engine, sync, report):
    sync(engine, "lru1")
    engine.submit(Unsync(robot="lru1"))
    report(engine, "lru1", "lru1-1", "running")
    applied = answer(engine, "lru1", 1, removed=["lru1-2"], kept=["lru1-1"])
    assert applied.notes == ["lru1 had already started lru1-1: it stays synchronized"]
    assert said(applied) == []


def test_a_retry_the_robot_did_not_queue(engine, sync, report):
    sync(engine, "lru1")
    report(engine, "lru1", "lru1-1", "running")
    report(engine, "lru1", "lru1-1", "failure")
    v = engine.submit(Retry(id="lru1-1")).value
    applied = answer(engine, "lru1", v["seq"], queued=[], reason="full")
    assert said(applied) == [("warning", "lru1 did not queue the retry lru1-1.2 of lru1-1: full")]


def test_a_queue_out_of_order_is_read_as_all_queued(engine):
    queue = [
        QueueEntry(id="lru1-1", status="idle_synchronized"),
        QueueEntry(id="lru1-2", status="running"),
        QueueEntry(id="lru1-1", status="idle_synchronized"),  # said twice: once
    ]
    applied = engine.submit(Reconcile(robot="lru1", queue=queue))
    assert said(applied) == [
        (
            "error",
            "lru1 registered a queue that is not an active skill followed by queued ones "
            "(lru1-1 idle_synchronized, lru1-2 running): read as all queued",
        ),
        (
            "warning",
            "lru1 holds lru1-1, lru1-2, which the mission had as unsynchronized: shown as "
            "synchronized again (unsync to take them back)",
        ),
    ]


def test_cancel_refusals(engine):
    assert refusal(lambda: engine.submit(Cancel(command=9))) == {
        "code": "unknown_command",
        "message": "no command 9 in this mission",
    }
    engine.submit(Sync(robot="lru1"))
    answer(engine, "lru1", 1, "refused", reason="nope")
    assert refusal(lambda: engine.submit(Cancel(command=1))) == {
        "code": "not_pending",
        "message": "command 1 (sync lru1-1, lru1-2) to lru1 is refused already: nope",
        "robot": "lru1",
    }


def test_a_control_that_applies_to_no_robot(engine):
    assert refusal(lambda: engine.submit(Control(op="pause"))) == {
        "code": "not_applicable",
        "message": "pause applies to no robot: lru1 has no running skill to pause; "
        "lru2 has no running skill to pause",
    }
    assert refusal(lambda: engine.submit(Control(op="pause", robot="lru2"))) == {
        "code": "not_applicable",
        "message": "lru2 has no running skill to pause",
        "robot": "lru2",
    }


def test_sync_refusals(engine, sync):
    sync(engine, "lru1", through="lru1-1")
    assert refusal(lambda: engine.submit(Sync(robot="lru1", through="lru1-1"))) == {
        "code": "not_idle",
        "message": "lru1-1 (drive to POI-A) on lru1 is already idle_synchronized: "
        "synchronize through an idle (unsynchronized) skill",
        "robot": "lru1",
        "skill": "lru1-1",
    }
    engine.submit(Sync(robot="lru1"))
    assert refusal(lambda: engine.submit(Sync(robot="lru1", through="lru1-2"))) == {
        "code": "locked",
        "message": "lru1-2 (look at POI-A): it is being synchronized to lru1 (command 1, queued)",
        "robot": "lru1",
        "skill": "lru1-2",
    }
    assert refusal(lambda: engine.submit(Sync(robot="lru1"))) == {
        "code": "nothing_to_sync",
        "message": "lru1 has no unsynchronized skill to synchronize "
        "(lru1-2 are being synchronized already)",
        "robot": "lru1",
    }


def test_unsync_refusals(engine, sync):
    sync(engine, "lru1")
    engine.submit(Unsync(robot="lru1", from_id="lru1-2"))
    assert refusal(lambda: engine.submit(Unsync(robot="lru1", from_id="lru1-2"))) == {
        "code": "locked",
        "message": "lru1-2 (look at POI-A): it is being unsynchronized from lru1 "
        "(command 1, queued)",
        "robot": "lru1",
        "skill": "lru1-2",
    }
    assert refusal(lambda: engine.submit(Unsync(robot="lru2"))) == {
        "code": "nothing_to_unsync",
        "message": "lru2 has no queued (idle_synchronized) skill to unsynchronize",
        "robot": "lru2",
    }
