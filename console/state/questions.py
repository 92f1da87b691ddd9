"""Robots' questions as the console shows them (no Textual here): which one
to open, and the sentences of the dialog, the palette and the alerts
screen. Every time is said in mission time by the model's clock."""

from __future__ import annotations

from backend.core.model import Mission, Question
from console.state.clock import MissionClock
from console.state.link import SHOWN_DELAY_S


def open_questions(mission: Mission | None) -> list[Question]:
    """The questions robots still wait on, oldest first."""
    if mission is None:
        return []
    return sorted(mission.open_questions(), key=lambda q: q.id)


def pick(mission: Mission | None, question_id: int | None) -> Question | None:
    """The question to open: that one (while open), or the oldest open one."""
    if mission is None:
        return None
    if question_id is None:
        shown = open_questions(mission)
        return shown[0] if shown else None
    q = mission.question(question_id)
    return q if q is not None and q.is_open else None


def not_open_text(mission: Mission | None, question_id: int | None) -> str:
    """Why there is nothing to answer."""
    if question_id is None:
        return "no robot asks a question now"
    q = mission.question(question_id) if mission is not None else None
    if q is None:
        return f"question #{question_id} is not in this mission"
    went = f" ('{q.choice}')" if q.choice else ""
    return f"question #{q.id} from {q.robot} is {q.state.value}{went}: nothing to answer"


def palette_title(q: Question) -> str:
    """'Answer question #3 from lru1…'."""
    return f"Answer question #{q.id} from {q.robot}…"


def due_text(q: Question, clock: MissionClock, delay_s: float | None = None) -> str:
    """'default wider at sim 12:34, in 4m12s' (mission time), or past it; with
    the robot's one-way delay (`delay_s`, wall seconds), how long an answer
    still has to leave the ground to reach the robot before the default."""
    left = (q.due - clock()).total_seconds()
    at = clock.stamp_text(q.due)
    if left <= 0:
        return f"default {q.default} applied on {q.robot} at {at} (not confirmed yet)"
    return f"default {q.default} at {at}, in {clock.duration_text(left)}" + _in_time(
        left, delay_s, clock
    )


def _in_time(left: float, delay_s: float | None, clock: MissionClock) -> str:
    """The link's share of the time left: an answer must cross it first
    (the on-board deadline alone would promise the operator too much)."""
    if delay_s is None or delay_s < SHOWN_DELAY_S:
        return ""
    link = clock.duration_text(delay_s)
    if left <= delay_s:
        return f"; an answer sent now arrives after it (the link takes {link})"
    return f"; answer within {clock.duration_text(left - delay_s)} (the link takes {link})"


def answer_text(q: Question, mission: Mission, clock: MissionClock) -> str:
    """An operator's answer on its way: who, when and its command's state ('' : none)."""
    if q.answer is None:
        return ""
    c = mission.command(q.command) if q.command is not None else None
    state = f"command {c.id} {c.state.value}" if c is not None else "its command settled"
    at = clock.stamp_text(q.answered_at)
    return f"answered {q.answer} by {q.answered_by or 'an operator'} at {at} ({state})"


def ended_text(q: Question) -> str:
    """How a question ended, for a note when its dialog closes by itself."""
    if q.is_open:
        return ""
    went = f" with {q.choice}" if q.choice else ""
    why = f" ({q.reason})" if q.reason else ""
    return f"question #{q.id} from {q.robot}: {q.state.value}{went}{why}"
