"""backend/core/limits.py: the one definition of the input limits, and the
walk that checks a value against them (files, messages and parameter values
use it)."""

from __future__ import annotations

from pathlib import Path

import pytest

from backend.core.library import check_params
from backend.core.limits import (
    ELIDED,
    LIMITS,
    Limits,
    MiB,
    brief,
    check_tree,
    echo,
    show_path,
    value_problem,
)
from backend.files.missions import load_library

ROOT = Path(__file__).resolve().parents[2]

SMALL = Limits(text=5, items=3, depth=3, value_depth=2, echo=4)


def test_defaults_fit_real_missions_and_document_themselves():
    # a 10,000-skill file is 2.4 MB and 282,000 YAML nodes; its JSON 3.9 MB
    assert LIMITS.file >= 4 * 2_452_892 and LIMITS.yaml_nodes >= 4 * 281_577
    assert LIMITS.payload >= 4 * 3_939_311
    # the JSON reader gives up past 200 levels: a parameter value in its
    # deepest envelope (a loaded mission in a journaled event) stays far below
    assert LIMITS.value_depth + 10 < LIMITS.depth < 200


@pytest.mark.parametrize(
    ("value", "path", "words"),
    [
        ("abcdef", (), "6 characters, more than the limit of 5 ('abcd'…)"),
        ({"k": ["ok", "toolong"]}, ("k", 1), "7 characters"),
        ([1, 2, 3, 4], (), "4 items, more than the limit of 3"),
        ({"a": 1, "b": 2, "c": 3, "d": 4}, (), "4 entries, more than the limit of 3"),
        ([[[[]]]], (0, 0, 0), "nested deeper than the limit of 3 levels"),
        ({"x": {"y": {"z": {}}}}, ("x", "y", "z"), "nested deeper than the limit of 3 levels"),
        ({"keykeykey": 1}, (), "a key of 9 characters, more than the limit of 5: 'keyk'…"),
    ],
)
def test_check_tree_names_the_path_and_the_limit(value, path, words):
    found = check_tree(value, depth=SMALL.depth, limits=SMALL)
    assert found is not None and found.path == path
    assert words in found.message


def test_within_the_limits_nothing_is_found():
    at_limit = {"abc": [["abcde", 1, None]], "b": 2.5, "c": True}  # 3 levels, 3 entries
    assert check_tree(at_limit, depth=SMALL.depth, limits=SMALL) is None
    assert value_problem(7) is None and value_problem(None) is None


def test_the_first_problem_in_document_order_is_reported():
    found = check_tree(["ok", "second!", {"a": "third!"}], depth=3, limits=SMALL)
    assert found is not None and found.path == (1,)


def test_any_nesting_is_measured_without_recursion():
    value: list = []
    for _ in range(100_000):  # far past Python's recursion limit
        value = [value]
    found = check_tree(value, depth=LIMITS.depth)
    assert found is not None and len(found.path) == 13 and found.path[-1] == ELIDED
    assert show_path(found.path) == "[0]" * 12 + "…"


def test_echo_and_paths_stay_short():
    assert echo("short") == "'short'"
    assert echo("x" * 1_000_000) == repr("x" * LIMITS.echo) + "…"
    assert brief(tuple(range(20)), keep=3) == (0, 1, 2, ELIDED)
    assert show_path(("tasks", "lru1", 3, "params", "goal")) == "tasks.lru1[3].params.goal"


def test_parameter_values_are_held_to_the_value_limits():
    """For files and operations alike (check_params is shared)."""
    library = load_library(ROOT / "missions" / "libraries" / "mars.yaml")
    nested: object = 1
    for _ in range(LIMITS.value_depth):
        nested = {"k": nested}
    params = {"target": {"x": 1, "y": 2}, "camera": {"deep": nested}}
    _, problems = check_params(
        library, "lru_science", "take_science_image", params, {}, markers={}, robots=set()
    )
    [p] = problems
    assert p.path[:2] == ("camera", "deep") and "limit of 16 levels" in p.message
    long_enum = {"target": {"x": 1, "y": 2}, "filter": "f" * (LIMITS.text + 1)}
    _, [p] = check_params(
        library, "lru_science", "take_science_image", long_enum, {}, markers={}, robots=set()
    )
    assert p.path == ("filter",) and "more than the limit of 10,000" in p.message
    assert len(p.message) < 200


def test_the_readme_documents_these_limits():
    """docs/protocol.md is generated from them; the README's table is written:
    it must say the same numbers."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    table = readme[readme.index("## Limits, and a journal") :]
    for row in (
        f"| string | {LIMITS.text:,} characters |",
        f"| list, mapping | {LIMITS.items:,} items, entries |",
        f"| nesting | {LIMITS.depth} levels |",
        f"| nesting of a parameter value | {LIMITS.value_depth} levels |",
        f"| message | {LIMITS.payload // MiB} MiB |",
        f"| file | {LIMITS.file // MiB} MiB |",
        f"| YAML nodes | {LIMITS.yaml_nodes:,} |",
        f"the first {LIMITS.echo} characters",
        "--recover",
    ):
        assert row in table, row


def test_messages_name_a_skill_by_the_start_of_a_long_label():
    """A label may be 10,000 characters: refusals and notes show its start."""
    from backend.core.model import SkillInstance

    s = SkillInstance(id="lru1-3", skill="recharge", label="y" * LIMITS.text)
    assert s.display() == "lru1-3 (" + "y" * 60 + "…)"
    assert SkillInstance(id="lru1-4", skill="recharge", label="short").display() == "lru1-4 (short)"
