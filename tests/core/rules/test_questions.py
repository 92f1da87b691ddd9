"""Robots ask, as rules: a robot's question opens (alerted), an operator's
answer travels the uplink as a command expiring at the question's due, the
robot says how it ended; refusals say what is wrong; a journal replays it."""

from __future__ import annotations

from datetime import timedelta

import pytest
from pydantic import ValidationError

from backend.core.alerts import AlertKind
from backend.core.model import CommandState, QuestionAnswer, QuestionState, Status
from backend.core.ops import (
    Answer,
    AnswerQuestion,
    Ask,
    AskEnded,
    Cancel,
    QueueEntry,
    Reconcile,
    UplinkSettle,
)

from .conftest import T0, bring

DUE = T0 + timedelta(minutes=5)


def ask(engine, *, ref="s1-1", seq=None, skill="lru2-2", **kw):
    seq = seq if seq is not None else engine.mission.report_seqs.get("lru2", 0) + 1
    fields = {
        "robot": "lru2",
        "seq": seq,
        "ref": ref,
        "skill": skill,
        "text": "Nothing found within 5 m: search wider?",
        "choices": ["wider", "give up"],
        "default": "wider",
        "timeout_s": 300,
        "at": T0,
        "due": DUE,
        **kw,
    }
    return engine.submit(Ask(**fields), actor="lru2")


def asked(engine):
    bring(engine, "lru2", "lru2-1", Status.SUCCESS)
    bring(engine, "lru2", "lru2-2", Status.RUNNING)
    engine.clock = lambda: T0 + timedelta(seconds=10)
    return ask(engine)


def robot_says(engine, message_type, **kw):
    seq = engine.mission.report_seqs.get("lru2", 0) + 1
    return engine.submit(message_type(robot="lru2", seq=seq, **kw), actor="lru2")


def test_a_robot_asks_and_the_question_opens_with_an_alert(engine):
    applied = asked(engine)
    (q,) = engine.mission.open_questions("lru2")
    assert (q.id, q.skill, q.choices, q.default, q.due) == (
        1,
        "lru2-2",
        ["wider", "give up"],
        "wider",
        DUE,
    )
    (alert,) = applied.alerts
    assert alert.kind == AlertKind.QUESTION and alert.question == 1 and alert.robot == "lru2"
    assert "search wider?" in alert.message and "5m" in alert.message
    again = ask(engine, seq=engine.mission.report_seqs["lru2"])  # sent again: applied once
    assert again.duplicate and len(engine.mission.questions["lru2"]) == 1


def test_an_answer_goes_up_the_uplink_and_the_robot_takes_it(engine):
    asked(engine)
    applied = engine.submit(AnswerQuestion(question=1, choice="give up"), actor="ops@console")
    c = engine.mission.command(applied.value["command"])
    assert c.op == "answer" and c.expires == DUE and c.skills == ["lru2-2"]
    assert c.command == QuestionAnswer(question=1, ref="s1-1", choice="give up", by="ops@console")
    q = engine.mission.question(1)
    assert (q.state, q.answer, q.answered_by, q.command) == (
        QuestionState.OPEN,
        "give up",
        "ops@console",
        c.id,
    )
    robot_says(engine, Answer, command=c.seq, outcome="applied", at=T0 + timedelta(seconds=40))
    q = engine.mission.question(1)
    assert (q.state, q.choice) == (QuestionState.ANSWERED, "give up")
    assert engine.mission.command(c.id).state == CommandState.ACKED
    assert engine.mission.open_questions() == []


def test_answers_that_cannot_apply_are_refused_with_a_sentence(engine, refused):
    asked(engine)
    refused(
        engine,
        lambda: engine.submit(AnswerQuestion(question=7, choice="wider")),
        "unknown_question",
        "no question 7",
        "1 (lru2)",
    )
    refused(
        engine,
        lambda: engine.submit(AnswerQuestion(question=1, choice="maybe")),
        "bad_choice",
        "wider, give up",
        "'maybe'",
        robot="lru2",
        skill="lru2-2",
    )
    engine.submit(AnswerQuestion(question=1, choice="wider"), actor="ann@c1")
    refused(
        engine,
        lambda: engine.submit(AnswerQuestion(question=1, choice="give up")),
        "already_answered",
        "'wider' by ann@c1",
        "queued",
    )
    robot_says(engine, AskEnded, ref="s1-1", outcome="default", choice="wider")
    refused(
        engine,
        lambda: engine.submit(AnswerQuestion(question=1, choice="give up")),
        "question_closed",
        "defaulted already with 'wider'",
    )


def test_an_answer_after_the_due_is_refused(engine, refused):
    asked(engine)
    engine.clock = lambda: DUE + timedelta(seconds=1)
    refused(
        engine,
        lambda: engine.submit(AnswerQuestion(question=1, choice="give up")),
        "too_late",
        "default 'wider'",
    )


def test_an_answer_cancelled_on_the_ground_lets_another_be_given(engine):
    asked(engine)
    first = engine.submit(AnswerQuestion(question=1, choice="wider"))
    engine.submit(Cancel(command=first.value["command"]))
    second = engine.submit(AnswerQuestion(question=1, choice="give up"))
    assert engine.mission.question(1).command == second.value["command"]


def test_the_default_applied_on_board_closes_it_and_says_so(engine):
    asked(engine)
    answer = engine.submit(AnswerQuestion(question=1, choice="give up"), actor="ann@c1")
    ended = robot_says(engine, AskEnded, ref="s1-1", outcome="default", choice="wider", at=DUE)
    q = engine.mission.question(1)
    assert (q.state, q.choice, q.closed) == (QuestionState.DEFAULTED, "wider", DUE)
    (alert,) = ended.alerts
    assert alert.level == "info" and "default 'wider'" in alert.message
    assert "'give up' by ann@c1 came too late" in alert.message
    # the robot then refuses the answer that came late: an alert names it
    c = engine.mission.command(answer.value["command"])
    refused_late = robot_says(engine, Answer, command=c.seq, outcome="refused", reason="defaulted")
    assert engine.mission.question(1).state == QuestionState.DEFAULTED
    assert any("refused" in a.message for a in refused_late.alerts)


def test_an_expired_answer_says_the_default_applies(engine):
    asked(engine)
    applied = engine.submit(AnswerQuestion(question=1, choice="give up"))
    settle = UplinkSettle(
        robot="lru2",
        ids=[applied.value["command"]],
        state=CommandState.EXPIRED,
        reason="expired before it could be sent",
        at=DUE,
    )
    (alert,) = engine.submit(settle, actor="server").alerts
    assert "goes on with the question's default" in alert.message


def test_a_robot_registering_without_its_question_withdraws_it(engine):
    asked(engine)
    ask(engine, ref="s1-2")
    engine.submit(
        Reconcile(
            robot="lru2",
            queue=[QueueEntry(id="lru2-2", status=Status.RUNNING)],
            asking=["s1-2"],
        ),
        actor="lru2",
    )
    q1, q2 = engine.mission.questions["lru2"]
    assert q1.state == QuestionState.WITHDRAWN and "registered without it" in q1.reason
    assert q2.is_open
    # a robot of an older SDK says nothing of its questions: they stay
    engine.submit(Reconcile(robot="lru2", queue=[QueueEntry(id="lru2-2", status=Status.RUNNING)]))
    assert engine.mission.question(2).is_open


def test_a_question_of_another_robots_skill_is_refused(engine, refused):
    asked(engine)
    refused(engine, lambda: ask(engine, skill="lru1-1", ref="x"), "bad_report", "lru1-1")


def test_a_question_breaking_its_limits_does_not_parse():
    base = {
        "robot": "lru2",
        "seq": 1,
        "ref": "r1",
        "skill": "lru2-2",
        "text": "search wider?",
        "timeout_s": 60,
        "at": T0,
        "due": DUE,
    }
    bad = [
        {"choices": ["a"], "default": "a"},
        {"choices": [str(i) for i in range(10)], "default": "0"},
        {"choices": ["a", "a"], "default": "a"},
        {"choices": ["a", "b"], "default": "c"},
        {"choices": ["a", "b\nc"], "default": "a"},
        {"choices": ["a", "x" * 41], "default": "a"},
        {"choices": ["a", "b"], "default": "a", "text": "x" * 501},
        {"choices": ["a", "b"], "default": "a", "timeout_s": 0},
    ]
    for fields in bad:
        with pytest.raises(ValidationError):
            Ask(**{**base, **fields})
