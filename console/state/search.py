"""`/`: find a skill by what an operator remembers of it — its id, label,
skill, robot, status or a parameter — and jump to it (no Textual here)."""

from __future__ import annotations

from dataclasses import dataclass

from backend.core.library import Library
from backend.core.model import SkillInstance
from console.state.model import ConsoleModel
from console.state.text import GLYPHS, STATUS_WORDS, param_summary, skill_title

LIMIT = 50  # matches listed (the list is for choosing, not reading)


@dataclass(frozen=True)
class Match:
    skill_id: str
    robot: str
    text: str  # one line: glyph, id, title, robot and status, parameters
    score: int


def search_skills(model: ConsoleModel, query: str, limit: int = LIMIT) -> list[Match]:
    """Skills whose id, label, skill, robot, status or parameters contain
    every word of `query` (any case), best first: an exact id, then ids and
    labels that start with the query, then plan order. Empty: every skill."""
    q = query.strip().lower()
    words = q.split()
    found: list[tuple[int, int, Match]] = []
    order = 0
    for robot in model.robot_order():
        for s in model.task(robot):
            order += 1
            match = _match(s, robot, q, words, model.library)
            if match is not None:
                found.append((-match.score, order, match))
    found.sort(key=lambda x: (x[0], x[1]))
    return [m for _, _, m in found[:limit]]


def _match(
    s: SkillInstance, robot: str, q: str, words: list[str], library: Library | None
) -> Match | None:
    """Skill `s` as a match for query `q` (None: a word of it is missing),
    scored: an exact id, an id or a title that starts with it, a title with it."""
    title = skill_title(s)
    params = param_summary(s, library)
    hay = f"{s.id} {title} {s.skill} {robot} {STATUS_WORDS[s.status]} {params}".lower()
    if not all(w in hay for w in words):
        return None
    score = (
        100 * (s.id.lower() == q)
        + 40 * s.id.lower().startswith(q)
        + 30 * title.lower().startswith(q)
        + 10 * (q in title.lower())
    )
    what = title if title == s.skill else f"{title} ({s.skill})"
    text = f"{GLYPHS[s.status]} {s.id}  {what}  — {robot}, {STATUS_WORDS[s.status]}"
    if params:
        text += f"  {params}"
    return Match(s.id, robot, text, score)
