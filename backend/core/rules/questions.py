"""Robots ask: a skill's question to the operators, their answer, how it ended.

A robot's `Ask` (numbered with its reports, applied once in its downlink's
order) opens a question and raises a `question` alert. An operator's
`AnswerQuestion` queues the answer on the robot's uplink like any command
(it expires when the question's default applies on board: the robot would
never take it later) and notes who answered; the question stays open until
the robot says how it ended: its answer to that command (`answered`), or
`AskEnded` (its default applied at the timeout, or its skill stopped or
ended: withdrawn). A robot that registers without a question the mission
has open for it (a restart ended the skill that asked) withdraws it.
"""

from __future__ import annotations

from typing import Any

from backend.core import events as ev
from backend.core.alerts import AlertKind, Level, RaisedAlert
from backend.core.contingency import span_text
from backend.core.model import (
    CommandState,
    Mission,
    Question,
    QuestionAnswer,
    QuestionState,
    UplinkCommand,
)
from backend.core.ops import AnswerQuestion, Ask, AskEnded, Reconcile
from backend.core.rules.base import Change, Refusal, Rule, Rules

_ENDED: dict[str, ev.Closed] = {
    "default": QuestionState.DEFAULTED,
    "withdrawn": QuestionState.WITHDRAWN,
}


def _alert(q: Question, message: str, level: Level = "warning") -> RaisedAlert:
    return RaisedAlert(
        level=level,
        kind=AlertKind.QUESTION,
        robot=q.robot,
        skill=q.skill,
        question=q.id,
        message=message,
    )


def _applied_already(rules: Rules, robot: str, seq: int) -> bool:
    return seq <= rules.mission.report_seqs.get(robot, 0)


def _duplicate(seq: int) -> Change:
    return Change([], [], {"ignored": f"message {seq} was applied already"}, None, True)


def by_ref(m: Mission, robot: str, ref: str) -> Question | None:
    """The robot's question it calls `ref` (the newest, should a ref repeat)."""
    return next((q for q in reversed(m.questions.get(robot, [])) if q.ref == ref), None)


def choices_text(q: Question) -> str:
    """'wider, give up (default wider)'."""
    return f"{', '.join(q.choices)} (default {q.default})"


# -- the robot asks ------------------------------------------------------------------


def ask(rules: Rules, op: Ask) -> Change:
    """A robot's question: open, alerted."""
    if _applied_already(rules, op.robot, op.seq):
        return _duplicate(op.seq)
    rules.task(op.robot)
    found = rules.mission.find(op.skill)
    if found is None or found[0] != op.robot:
        raise Refusal(
            "bad_report",
            f"{op.robot} asks for skill {op.skill}, which is not one of its skills: the "
            "question was not opened (its default applies on board)",
            robot=op.robot,
            skill=op.skill,
        )
    q = Question(
        id=rules.mission.next_question,
        robot=op.robot,
        ref=op.ref,
        skill=op.skill,
        text=op.text,
        choices=op.choices,
        default=op.default,
        timeout_s=op.timeout_s,
        asked=op.at,
        due=op.due,
    )
    message = (
        f"{op.robot} asks ({q.title()}): {op.text} — {choices_text(q)}; its default "
        f"applies on board after {span_text(round(op.timeout_s))} of mission time"
    )
    events: list[ev.Event] = [
        ev.ReportSeq(robot=op.robot, seq=op.seq),
        ev.QuestionAsked(question=q),
    ]
    return Change(events, [], {"question": q.id}, None, alerts=(_alert(q, message),))


def ask_ended(rules: Rules, op: AskEnded) -> Change:
    """A question the robot ended without an operator's answer."""
    if _applied_already(rules, op.robot, op.seq):
        return _duplicate(op.seq)
    rules.task(op.robot)
    events: list[ev.Event] = [ev.ReportSeq(robot=op.robot, seq=op.seq)]
    q = by_ref(rules.mission, op.robot, op.ref)
    if q is None:
        raise Refusal(
            "bad_report",
            f"{op.robot} ended its question {op.ref}, which it never asked here",
            robot=op.robot,
        )
    if not q.is_open:  # closed on the ground already (withdrawn at a registration)
        return Change(events, [], {"question": q.id, "state": q.state.value}, None)
    state = _ENDED[op.outcome]
    at = op.at or rules.clock()
    events.append(
        ev.QuestionClosed(id=q.id, state=state, choice=op.choice, at=at, reason=op.reason)
    )
    alerts = () if state == QuestionState.WITHDRAWN else (_alert(q, _defaulted(q, op), "info"),)
    return Change(events, [], {"question": q.id, "state": state.value}, None, alerts=alerts)


def _defaulted(q: Question, op: AskEnded) -> str:
    late = (
        f"; the answer '{q.answer}' by {q.answered_by or 'an operator'} came too late"
        if (q.answer)
        else ""
    )
    return (
        f"{q.robot} had no answer to {q.title()} in time: it went on with the default "
        f"'{op.choice or q.default}'{late}"
    )


# -- an operator answers -------------------------------------------------------------


def answer_question(rules: Rules, op: AnswerQuestion) -> Change:
    """The answer goes up the robot's uplink; the question stays open until
    the robot says it took it."""
    m = rules.mission
    q = m.question(op.question)
    if q is None:
        raise Refusal("unknown_question", f"no question {op.question} in this mission{_open(m)}")
    _check_answerable(rules, q)
    if op.choice not in q.choices:
        raise Refusal(
            "bad_choice",
            f"{q.title()} offers {', '.join(q.choices)}, not '{op.choice}'",
            robot=q.robot,
            skill=q.skill,
        )
    now = rules.clock()
    c = UplinkCommand(
        id=m.next_command,
        robot=q.robot,
        seq=m.uplink_seqs.get(q.robot, 0) + 1,
        op="answer",
        command=QuestionAnswer(question=q.id, ref=q.ref, choice=op.choice, by=rules.actor),
        skills=[q.skill],
        created=now,
        expires=q.due,
    )
    events: list[ev.Event] = [
        ev.CommandQueued(command=c),
        ev.QuestionAnswered(id=q.id, choice=op.choice, by=rules.actor, at=now, command=c.id),
    ]
    value = {
        "command": c.id,
        "robot": c.robot,
        "seq": c.seq,
        "state": c.state.value,
        "skills": list(c.skills),
        "expires": q.due.isoformat(),
        "question": q.id,
    }
    return Change(events, [], value, None)


def _open(m: Mission) -> str:
    shown = [f"{q.id} ({q.robot})" for q in m.open_questions()]
    return f" (open questions: {', '.join(shown)})" if shown else " (none is open)"


def _check_answerable(rules: Rules, q: Question) -> None:
    """Refused once it ended, while an answer is on its way or taken, or
    when its default applied on board already."""
    where = {"robot": q.robot, "skill": q.skill}
    if not q.is_open:
        went = f" with '{q.choice}'" if q.choice else ""
        raise Refusal(
            "question_closed", f"{q.title()} is {q.state.value} already{went}{_why(q)}", **where
        )
    c = _answer_under_way(rules, q)
    if c is not None:
        raise Refusal(
            "already_answered",
            f"{q.title()} was answered '{q.answer}' by {q.answered_by or 'an operator'}: "
            f"{c.title()} is {c.state.value} (cancel it first to answer otherwise)",
            **where,
        )
    if rules.clock() >= q.due:
        raise Refusal(
            "too_late",
            f"{q.title()}: its default '{q.default}' applied on {q.robot} at its timeout; "
            "an answer would arrive after it",
            **where,
        )


def _answer_under_way(rules: Rules, q: Question) -> UplinkCommand | None:
    """The command taking the answer given already, while it is on its way
    to the robot or taken by it."""
    c = rules.mission.command(q.command) if q.command is not None else None
    return c if c is not None and c.state in _UNDER_WAY else None


_UNDER_WAY = (CommandState.QUEUED, CommandState.SENT, CommandState.ACKED)


def _why(q: Question) -> str:
    return f" ({q.reason})" if q.reason else ""


# -- hooks of the uplink's rules -------------------------------------------------------


def applied_answer(fx: Any) -> None:
    """The robot took an operator's answer (its `Answer` to the command):
    the question is answered (`fx`: backend.core.rules.uplink's effects)."""
    cmd = fx.c.command
    assert isinstance(cmd, QuestionAnswer)
    q = fx.rules.mission.question(cmd.question)
    if q is None or not q.is_open:
        return
    at = fx.op.at or fx.rules.clock()
    fx.events.append(
        ev.QuestionClosed(id=q.id, state=QuestionState.ANSWERED, choice=cmd.choice, at=at)
    )


def reconciled(rules: Rules, op: Reconcile) -> list[ev.Event]:
    """A robot registered asking `op.asking`: its other open questions are
    withdrawn (a restart ended the skill that asked)."""
    if op.asking is None:
        return []
    asking = set(op.asking)
    why = f"{op.robot} registered without it: the skill that asked no longer waits"
    return [
        ev.QuestionClosed(id=q.id, state=QuestionState.WITHDRAWN, at=rules.clock(), reason=why)
        for q in rules.mission.open_questions(op.robot)
        if q.ref not in asking
    ]


RULES: dict[type[Any], Rule] = {
    Ask: ask,
    AskEnded: ask_ended,
    AnswerQuestion: answer_question,
}
