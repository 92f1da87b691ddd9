"""The event log's lines and filter, and the alert book's notifications, word
for word: what an operator reads of each event kind."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

from backend.core import events as ev
from backend.core.model import Barrier, Policies, SkillInstance, Status
from console.state.eventlog import AlertBook, EventLog, LogEntry, entry_matches, toast_text

AT = datetime(2026, 1, 1, 12, 0, tzinfo=UTC)
OWNERS = {"lru1-1": "lru1", "lru1-2": "lru1", "lru2-1": "lru2", "lru2-2": "lru2"}


def _lines(op: str, *events: ev.Event, actor: str = "ana@ground-1") -> list[LogEntry]:
    log = EventLog()
    batch = ev.EventBatch(revision=7, op=op, actor=actor, events=list(events))
    return log.add_batch(batch, OWNERS.get, AT)


def test_an_operation_is_one_line_naming_each_change_and_its_robots():
    (line,) = _lines(
        "edit",
        ev.SkillMoved(robot="lru2", id="lru2-1", index=1),
        ev.SkillEdited(id="lru1-2", label="find a stone", params={"area": "x" * 40}),
        ev.BarrierSet(id="b1", barrier=Barrier(skills=["lru1-1", "lru2-2"])),
        ev.SkillStatusChanged(id="lru1-1", info="waiting"),
    )
    assert line.kind == "operation" and line.skill == "lru2-1"
    assert line.text == (
        "edit: lru2-1 → #2; lru1-2 label=find a stone, params; "
        "barrier b1 (lru1-1, lru2-2); lru1-1 status_info=waiting"
    )
    assert line.robots == ["lru2", "lru1"]
    assert (line.user, line.client, line.op, line.revision) == ("ana", "ground-1", "edit", 7)


def test_an_operation_of_many_changes_counts_the_rest():
    (line,) = _lines(
        "",
        ev.SkillAdded(robot="lru1", index=0, skill=SkillInstance(id="lru1-9", skill="recharge")),
        ev.SkillRemoved(robot="lru2", id="lru2-2"),
        ev.SkillStatusChanged(id="lru1-1", status=Status.IDLE_SYNCHRONIZED),
        ev.BarrierRemoved(id="b1"),
        ev.MarkerRemoved(name="POI-A"),
        ev.SkillEdited(id="lru2-1", policies=Policies(retries=2)),
        actor="ground-2",
    )
    assert line.text == (
        "change: +lru1-9 (recharge); -lru2-2; lru1-1 idle_synchronized; "
        "barrier b1 removed; … 2 more"
    )
    assert line.robots == ["lru1", "lru2"] and line.skill == "lru2-2"
    assert (line.user, line.client) == ("", "ground-2")


def test_a_report_is_a_line_per_status_its_robot_from_the_plan():
    lines = _lines(
        "report",
        ev.SkillStatusChanged(id="lru1-1", status=Status.RUNNING),
        ev.SkillStatusChanged(id="lru1-1", info="no status"),
        ev.SkillStatusChanged(id="lru3-1", status=Status.FAILURE, info="stuck"),
        ev.ReportSeq(robot="lru1", seq=3),
        actor="lru3",
    )
    assert [(x.kind, x.robots, x.skill, x.text) for x in lines] == [
        ("report", ["lru1"], "lru1-1", "▶ lru1-1 running"),
        ("failure", ["lru3"], "lru3-1", "✗ lru3-1 failure: stuck"),
    ]
    assert [x.seq for x in lines] == [1, 2]
    assert {(x.client, x.op, x.revision) for x in lines} == {("lru3", "report", 7)}


def test_the_filter_matches_robot_kind_and_words():
    entry = LogEntry(
        seq=1, at=AT, kind="failure", robots=["lru1"], skill="lru1-3", text="✗ lru1-3 failed"
    )
    assert entry_matches(entry, "robot:LRU kind:fail lru1-3")
    assert not entry_matches(entry, "robot")  # no colon: a word like any other
    assert entry_matches(entry, "LRU1-3 FAILED")
    assert not entry_matches(entry, "skill:lru1-3")  # no such field: a word too
    assert not entry_matches(entry, "robot:lru2")
    assert not entry_matches(entry, "kind:report")
    assert not entry_matches(entry, "stuck")
    assert entry_matches(entry, "")


def test_robots_offline_together_are_one_notification():
    book = AlertBook()
    first = book.add("malformed", "lru1 went offline", AT, robot="lru1")
    assert first is not None
    first.kind = "offline"
    assert toast_text(book, first) == ("Robots offline", "lru1 went offline")
    later = [
        book.add("malformed", f"{r} went offline", AT + timedelta(seconds=s), robot=r)
        for r, s in (("lru2", 10), ("ardea", 20), ("lander", 90))
    ]
    for a in later:
        assert a is not None
        a.kind = "offline"
    assert toast_text(book, later[1]) == ("Robots offline", "lru1, lru2 and ardea went offline")
    assert toast_text(book, later[2]) == ("Robots offline", "lander went offline")
    book.acknowledge(first.id)
    assert toast_text(book, later[0]) == ("Robots offline", "lru2 and ardea went offline")


def test_another_alert_is_titled_by_its_robot_and_skill():
    book = AlertBook()
    a = book.add("refusal", "not now", AT, robot="lru1", skill="lru1-2")
    b = book.add("malformed", "unreadable", AT)
    assert a is not None and b is not None
    assert toast_text(book, a) == ("lru1 · lru1-2", "not now")
    assert toast_text(book, b) == ("Alert", "unreadable")
