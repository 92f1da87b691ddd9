"""Waivers and the sync gate: a sync sending a skill named by an unwaived
plan error is refused with a sentence naming the checks and how to waive
them; a waiver (journaled as events, undoable) lets it go."""

from __future__ import annotations

from backend.core import events as ev
from backend.core.model import Mission, Status
from backend.core.ops import AddBarrier, AddSkill, Sync, Undo, Unwaive, Waive

from .conftest import status_of, sync

DEADLOCK = "barrier.deadlock:b1+b2"


def crossed(engine):
    """lru1: lru1-1 then lru1-2; lru2: lru2-1 then lru2-2; b1 = lru1-1 + lru2-2,
    b2 = lru1-2 + lru2-1: each waits for the other."""
    engine.submit(AddBarrier(ids=["lru1-1", "lru2-2"]))
    engine.submit(AddBarrier(ids=["lru1-2", "lru2-1"]))


def test_a_sync_through_a_deadlocked_barrier_is_refused_naming_the_check(engine, refused):
    crossed(engine)
    r = refused(
        engine,
        lambda: engine.plan_sync(Sync(robot="lru1")),
        "plan_errors",
        DEADLOCK,
        "ctl waive",
        robot="lru1",
    )
    assert "lru1 must pass b1 (lru1-1) before it reaches b2 (lru1-2)" in r.message


def test_a_sync_of_skills_no_error_names_goes_through(engine):
    crossed(engine)
    engine.submit(
        AddSkill(
            robot="lru1", skill="take_science_image", at=0, params={"target": {"x": 1, "y": 1}}
        )
    )
    first = engine.mission.tasks["lru1"][0].id
    sync(engine, "lru1", through=first)
    assert status_of(engine, first) == Status.IDLE_SYNCHRONIZED


def test_a_waiver_lets_the_sync_go_and_is_an_event(engine):
    crossed(engine)
    applied = engine.submit(Waive(check=DEADLOCK, reason="we release them by hand"))
    (event,) = applied.events
    assert isinstance(event, ev.WaiverSet) and event.check == DEADLOCK
    w = engine.mission.waivers[DEADLOCK]
    assert w.reason == "we release them by hand" and w.revision == applied.revision
    sync(engine, "lru1")
    assert status_of(engine, "lru1-2") == Status.IDLE_SYNCHRONIZED


def test_waiving_again_replaces_the_reason_and_the_same_reason_changes_nothing(engine):
    engine.submit(Waive(check=DEADLOCK, reason="one"))
    rev = engine.mission.revision
    assert engine.submit(Waive(check=DEADLOCK, reason=" one ")).events == []
    assert engine.mission.revision == rev
    engine.submit(Waive(check=DEADLOCK, reason="two"))
    assert engine.mission.waivers[DEADLOCK].reason == "two"
    engine.submit(Undo(), client="")
    assert engine.mission.waivers[DEADLOCK].reason == "one"


def test_unwaive_removes_it_and_the_gate_closes_again(engine, refused):
    crossed(engine)
    engine.submit(Waive(check=DEADLOCK, reason="for now"))
    applied = engine.submit(Unwaive(check=DEADLOCK))
    assert isinstance(applied.events[0], ev.WaiverRemoved)
    assert DEADLOCK not in engine.mission.waivers
    refused(engine, lambda: engine.plan_sync(Sync(robot="lru2")), "plan_errors", DEADLOCK)


def test_waive_and_unwaive_refuse_what_makes_no_sense(engine, refused):
    refused(engine, lambda: engine.submit(Unwaive(check=DEADLOCK)), "unknown_waiver", DEADLOCK)
    refused(
        engine,
        lambda: engine.submit(Waive(check="barrier.nonsense:b1", reason="x")),
        "unknown_check",
        "barrier.nonsense",
        "barrier.deadlock",
    )
    refused(
        engine, lambda: engine.submit(Waive(check=DEADLOCK, reason="   ")), "bad_request", "reason"
    )


def test_waivers_replay_into_a_mirror_and_survive_a_mission_file_round_trip(engine):
    mirror = engine.mission.copy_deep()
    applied = engine.submit(Waive(check=DEADLOCK, reason="ok"))
    mirror = ev.apply_events(mirror, applied.batch())
    assert mirror.waivers == engine.mission.waivers
    again = Mission.model_validate_json(engine.mission.model_dump_json())
    assert again.waivers[DEADLOCK].reason == "ok"


def test_the_gate_refuses_a_sync_before_any_command_is_queued(engine, refused):
    """Protocol 2's sync (a command on the robot's uplink) passes the same
    gate: refused, nothing queued, nothing locked; waived, it is queued."""
    crossed(engine)
    before = engine.mission.revision
    refused(engine, lambda: engine.submit(Sync(robot="lru1")), "plan_errors", DEADLOCK)
    assert engine.mission.revision == before and not engine.mission.pending_commands("lru1")
    engine.submit(Waive(check=DEADLOCK, reason="released by hand"))
    queued = engine.submit(Sync(robot="lru1"))
    assert queued.value["skills"] == ["lru1-1", "lru1-2"]
    assert [c.id for c in engine.mission.pending_commands("lru1")] == [queued.value["command"]]
