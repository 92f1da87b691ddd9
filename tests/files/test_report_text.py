"""The plan-against-actual report as a person reads it, word for word."""

from __future__ import annotations

import time
from datetime import UTC, datetime

import pytest

from backend.core import events as ev
from backend.core.model import Mission, Status
from backend.files.record.journal import Batch
from backend.files.record.report import (
    ActorRow,
    PlanReport,
    RefusalRow,
    SkillRow,
    WaiverRow,
    _Pass,
    report_text,
)


@pytest.fixture
def utc(monkeypatch):
    monkeypatch.setenv("TZ", "UTC")
    time.tzset()
    yield
    monkeypatch.undo()
    time.tzset()


def _at(h: int, m: int, s: int) -> datetime:
    return datetime(2026, 12, 2, h, m, s, tzinfo=UTC)


def test_every_section_says_what_it_holds(utc):
    failed = SkillRow(
        id="lru1-3", robot="lru1", skill="drive_to", status=Status.FAILURE,
        predicted_start=_at(8, 0, 0), predicted_end=_at(8, 1, 0),
        started=_at(8, 0, 30), finished=_at(8, 4, 0),
        failures=["stuck", "stuck again"], retried_as="lru1-3.2",
    )  # fmt: skip
    retry = SkillRow(
        id="lru1-3.2", robot="lru1", skill="drive_to", status=Status.SUCCESS,
        started=_at(8, 5, 0), retry_of="lru1-3",
    )  # fmt: skip
    early = SkillRow(
        id="lru2-1", robot="lru2", skill="take_image", status=Status.SUCCESS,
        predicted_start=_at(8, 0, 10), started=_at(8, 0, 5),
    )  # fmt: skip
    lost = SkillRow(
        id="lru2-2", robot="lru2", skill="take_image", status=Status.FAILURE,
        finished=_at(8, 2, 0), failures=["dark"],
    )  # fmt: skip
    report = PlanReport(
        journal="m.db", mission="survey", start=_at(7, 59, 0), end=None, changes=12,
        gap="older snapshots were not kept",
        skills=[failed, retry, early, lost], deleted_unsynchronized=2, unsynchronized_at_end=1,
        waivers=[
            WaiverRow(check="energy", reason="charged", by="alice", at=_at(8, 0, 1)),
            WaiverRow(check="reach", reason="near", by="bob", at=_at(8, 0, 2),
                      withdrawn=_at(8, 3, 0)),
        ],
        refusals=[RefusalRow(at=_at(8, 1, 1), robot="lru1", what="cancel 3", reason="busy")],
        actors=[ActorRow(actor="alice", operations={"add": 3, "sync": 1})],
    )  # fmt: skip
    assert report_text(report) == (
        "Plan against actual: survey (m.db), 07:59:00 to - ground wall time, 12 changes\n"
        "times: wall time (local) throughout, lateness in wall seconds: the journal records "
        "no simulator's mission clock (a simulated mission's sim times cannot be shown)\n"
        "note: older snapshots were not kept\n"
        "\n"
        "Skills (start and end: as forecast when synchronized → as the robot did it, "
        "robot wall time; (+late / -early))\n"
        "  lru1     lru1-3         drive_to           failure           "
        "start 08:00:00→08:00:30 (+30s)  end 08:01:00→08:04:00 (+3.0m)  "
        "failed: stuck; stuck again; retried as lru1-3.2\n"
        "  lru1     lru1-3.2       drive_to           success           "
        "start -→08:05:00  end -→-  retry of lru1-3\n"
        "  lru2     lru2-1         take_image         success           "
        "start 08:00:10→08:00:05 (-5s)  end -→-\n"
        "  lru2     lru2-2         take_image         failure           "
        "start -→-  end -→08:02:00  failed: dark; no forecast sent with its sync\n"
        "  (2 deleted before being synchronized, 1 never synchronized)\n"
        "\n"
        "Failures and retries: 2 failed\n"
        "  lru1-3 (lru1) at 08:04:00: stuck again, retried as lru1-3.2\n"
        "  lru2-2 (lru2) at 08:02:00: dark, not retried\n"
        "\n"
        "Waivers: 2\n"
        "  energy: 'charged' by alice at 08:00:01\n"
        "  reach: 'near' by bob at 08:00:02, withdrawn 08:03:00\n"
        "\n"
        "Refusals: 1\n"
        "  08:01:01 lru1: cancel 3: busy\n"
        "\n"
        "Overdue verifications: none listed\n"
        "  (verification stages of commands (queued, sent, received, started, completed, "
        "each with a due time) do not exist yet; this section lists the overdue ones once "
        "they do)\n"
        "\n"
        "Who did what\n"
        "  alice: 4 (add 3, sync 1)\n"
    )


def test_a_report_without_skills_says_none_was_synchronized(utc):
    report = PlanReport(
        journal="m.db", mission="m", start=None, end=None, changes=0,
        skills=[], waivers=[], refusals=[], actors=[],
    )  # fmt: skip
    text = report_text(report)
    assert "note:" not in text
    # the clock is named: wall, whether or not a simulator ran (the journal cannot tell)
    assert text.startswith("Plan against actual: m (m.db), - to - ground wall time, 0 changes\n")
    assert "\ntimes: wall time (local) throughout" in text
    assert "  none was synchronized\n  (0 deleted before being synchronized, 0 never" in text
    assert "Failures and retries: 0 failed\n\nWaivers: 0\n\nRefusals: 0\n\n" in text
    assert text.endswith("Who did what\n")


def test_a_refused_downlink_message_is_a_refusal_of_its_robot():
    op = {"op": "downlink_refused", "robot": "lru1", "seq": 4, "message": "no skill 'x'"}
    p = _Pass(Mission(name="m", library="lib.yaml"))
    p.batch(Batch(7, 60.0, "lru1", "", op, ev.EventBatch(revision=7, events=[])))
    p.batch(
        Batch(8, 61.0, "lru2", "", {"op": "downlink_refused"}, ev.EventBatch(revision=8, events=[]))
    )
    assert p.refusals == [
        RefusalRow(at=datetime.fromtimestamp(60.0, UTC), robot="lru1", what="downlink message 4",
                   reason="no skill 'x'"),
        RefusalRow(at=datetime.fromtimestamp(61.0, UTC), robot="", what="downlink message ?",
                   reason=""),
    ]  # fmt: skip
    assert {a: dict(c) for a, c in p.actors.items()} == {
        "lru1": {"downlink_refused": 1}, "lru2": {"downlink_refused": 1}
    }  # fmt: skip
