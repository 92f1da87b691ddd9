"""ctl for robots' questions (issue 29): `questions [ROBOT...]` lists the
open ones with how long until each one's default applies on board (mission
time), `answer Q CHOICE [--wait [S]]` answers one (its command goes up the
robot's uplink like any other); the watch phrases of their events."""

from __future__ import annotations

import argparse
import json
from datetime import UTC, datetime
from typing import Any

from pydantic import ValidationError

from backend.cli.ctl.errors import UsageError
from backend.core import ops
from backend.core.model import Question
from backend.exit_codes import EXIT_OK

# ---------------------------------------------------------------- arguments


def questions_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("robots", nargs="*", metavar="ROBOT", help="only these robots' questions")


def answer_arguments(p: argparse.ArgumentParser, wait: Any) -> None:
    p.add_argument("question", type=int, metavar="Q", help="the question's number")
    p.add_argument(
        "choice",
        metavar="CHOICE",
        help="one of its choices (quote one with spaces), or its number 1..9 as listed",
    )
    wait(p, expire=False)


# ---------------------------------------------------------------- the builder


def _numbered(q: Any, choice: str) -> str:
    """The choice a number names, as `ctl questions` lists them (else `choice`)."""
    if q is None or choice in q.choices or not choice.isdigit():
        return choice
    n = int(choice)
    if not 1 <= n <= len(q.choices):
        raise UsageError(f"answer: question {q.id} has choices 1 to {len(q.choices)}, not {n}")
    return str(q.choices[n - 1])


def build_answer(args: argparse.Namespace, known: Any) -> Any:
    """The answer; CHOICE may be a choice's number as `ctl questions` lists it."""
    q = known.mission.question(args.question) if known.mission is not None else None
    try:
        return ops.AnswerQuestion(question=args.question, choice=_numbered(q, args.choice.strip()))
    except ValidationError as e:
        raise UsageError(f"answer: {e.errors()[0]['msg']} ({args.choice!r})") from None


# ---------------------------------------------------------------- the view


def mission_left_s(q: Question, now: datetime) -> float:
    """Mission seconds until its default applies on board (0 once past): the
    wall time left at the robot's pace (its timeout over the wall time it
    gave it, the sim's speed)."""
    wall = (q.due - q.asked).total_seconds()
    left = (q.due - now).total_seconds()
    return max(0.0, left * q.timeout_s / wall) if wall > 0 else 0.0


def _span(seconds: float) -> str:
    s = round(seconds)
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


def question_json(q: Question, client: Any, now: datetime) -> dict[str, Any]:
    c = client.mission.command(q.command) if q.command is not None else None
    return {
        **q.model_dump(mode="json"),
        "default_in_s": mission_left_s(q, now),
        "answer_command": {"id": c.id, "state": c.state.value} if c is not None else None,
    }


def _when(q: Question, left: float) -> str:
    if left > 0:
        return f"its default '{q.default}' applies in {_span(left)} of mission time"
    return f"past its due: '{q.default}' applies on board (not confirmed yet)"


def _answered(q: Question, client: Any) -> list[str]:
    """An operator's answer on its way, and its command's state."""
    if q.answer is None:
        return []
    c = client.mission.command(q.command) if q.command is not None else None
    state = f"command {c.id} {c.state.value}" if c is not None else "its command settled"
    return [f"  answered '{q.answer}' by {q.answered_by or 'an operator'} ({state})"]


def question_lines(q: Question, client: Any, now: datetime) -> list[str]:
    """'question 3 lru2 (lru2-4): Nothing found: search wider?' and its choices."""
    lines = [f"question {q.id} {q.robot} ({q.skill}): {q.text}"]
    lines += [f"  {i}. {choice}" for i, choice in enumerate(q.choices, 1)]
    lines.append(f"  {_when(q, mission_left_s(q, now))}")
    return lines + _answered(q, client)


def _check_robots(client: Any, only: list[str]) -> None:
    unknown = [r for r in only if r not in client.mission.robots]
    if unknown:
        known = ", ".join(client.mission.robots) or "none"
        raise UsageError(
            f"questions: no robot {', '.join(unknown)} in this mission (robots: {known})"
        )


def questions_json(questions: list[Question], client: Any, now: datetime) -> str:
    out = {
        "revision": client.revision,
        "questions": [question_json(q, client, now) for q in questions],
    }
    return json.dumps(out, ensure_ascii=False)


def questions_text(questions: list[Question], client: Any, now: datetime) -> str:
    if not questions:
        return "no open questions"
    lines = [line for q in questions for line in question_lines(q, client, now)]
    return "\n".join([*lines, "answer with: missionctl ctl answer Q CHOICE"])


async def questions_view(client: Any, args: argparse.Namespace) -> int:
    only = list(args.robots or [])
    _check_robots(client, only)
    open_ = [q for q in client.mission.open_questions() if not only or q.robot in only]
    show = questions_json if args.json else questions_text
    print(show(open_, client, datetime.now(UTC)), flush=True)
    return EXIT_OK


# ---------------------------------------------------------------- outcomes and watch


def answered(o: Any) -> str:
    v = o.value
    return (
        f"queued for {v.get('robot', '?')}, command {v.get('command', '?')}: answer "
        f"'{o.op.choice}' to question {o.op.question} {o.at}"
    )


DESCRIBE = {"answer_question": answered}

EVENT_TEXT = {
    "question_asked": lambda e: (
        f"question {e.question.id} from {e.question.robot} ({e.question.skill}): "
        f"{e.question.text} [{' / '.join(e.question.choices)}; default {e.question.default}]"
    ),
    "question_answered": lambda e: (
        f"question {e.id} answered '{e.choice}' by {e.by or 'an operator'} (command {e.command})"
    ),
    "question_closed": lambda e: (
        f"question {e.id} {e.state.value}"
        + (f": {e.choice}" if e.choice else "")
        + (f" ({e.reason})" if e.reason else "")
    ),
}
