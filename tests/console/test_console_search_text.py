"""The skill search's lines and scores, word for word: an exact id first,
then ids and titles that start with the query, then plan order."""

from __future__ import annotations

from console_state import MARS_FLEET, fleet, mars_mid_execution

from console.state.model import ConsoleModel
from console.state.search import search_skills


def _model() -> ConsoleModel:
    b = mars_mid_execution()
    m = ConsoleModel()
    m.load(b.snapshot(), b.library, fleet(MARS_FLEET))
    return m


def test_a_match_says_glyph_id_title_robot_status_and_parameters():
    found = search_skills(_model(), "recharge")
    assert [(x.skill_id, x.robot, x.score, x.text) for x in found] == [
        ("lru1-5", "lru1", 40, "○ lru1-5  recharge  — lru1, idle"),
        ("ardea-4", "ardea", 40, "● ardea-4  recharge  — ardea, queued"),
    ]
    (exact,) = search_skills(_model(), "LRU1-1")
    assert (exact.score, exact.text) == (
        140,
        "✓ lru1-1  drive to POI-A (drive_to)  — lru1, success  goal@POI-A",
    )
    assert [x.skill_id for x in search_skills(_model(), "", 3)] == ["lru1-1", "lru1-2", "lru1-3"]
