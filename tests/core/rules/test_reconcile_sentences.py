"""A robot's registration that disagrees with the mission, word for word:
what it says of skills the robot lost, holds as idle or must drop, and
the events that put the task back in order. Pinned before reconcile is
reshaped (issue 27)."""

from __future__ import annotations

from backend.core import events as ev
from backend.core.ops import QueueEntry, Reconcile

from .test_uplink_sentences import said


def test_a_lost_skill_and_a_stray_say_so(engine, sync):
    sync(engine, "lru1")
    queue = [
        QueueEntry(id="lru1-2", status="idle_synchronized"),
        QueueEntry(id="zz-9", status="idle_synchronized"),
    ]
    applied = engine.submit(Reconcile(robot="lru1", queue=queue))
    c = engine.mission.uplink["lru1"][-1]
    assert said(applied) == [
        ("warning", "lru1 no longer had lru1-1: returned to the plan"),
        (
            "warning",
            "lru1 holds zz-9, which this mission does not give it (or not as it has them): "
            f"asked it to drop them (command {c.id})",
        ),
    ]
    assert applied.value == {"unsynchronized": ["lru1-1"], "adopted": [], "dropped": ["zz-9"]}
    status = [e for e in applied.events if isinstance(e, ev.SkillStatusChanged)]
    assert [(e.id, e.status, e.info) for e in status] == [
        ("lru1-1", "idle", "returned to the plan: lru1 no longer had it")
    ]
    assert [s.id for s in engine.mission.tasks["lru1"]][:2] == ["lru1-2", "lru1-1"]
    assert c.op == "reconcile" and c.skills == ["zz-9"]


def test_a_held_skill_whose_status_moved_is_reported_once(engine, sync):
    sync(engine, "lru1")
    queue = [
        QueueEntry(id="lru1-1", status="running"),
        QueueEntry(id="lru1-2", status="idle_synchronized"),
    ]
    applied = engine.submit(Reconcile(robot="lru1", queue=queue))
    status = [(e.id, e.status) for e in applied.events if isinstance(e, ev.SkillStatusChanged)]
    assert status == [("lru1-1", "running")]
    assert said(applied) == []
    assert applied.value == {"unsynchronized": [], "adopted": [], "dropped": []}
