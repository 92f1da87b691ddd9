"""The sentences `pydantic_issues` says for each kind of pydantic error, and
where (`_clean_loc`): an operator reads these, so they are pinned word for word."""

from __future__ import annotations

from typing import Any

import pytest

from backend.core.model import NAME_PATTERN
from backend.files.diagnostics import _clean_loc, _sentence


def err(type_: str, loc: tuple[Any, ...] = ("robots", "lru1", "x"), **extra: Any) -> Any:
    return {"type": type_, "loc": loc, "msg": "pydantic's words", "input": 7, **extra}


SENTENCES = [
    (err("missing"), "missing required field 'x'"),
    (err("extra_forbidden", ("speed",)), "unknown field 'speed'"),
    (
        err("literal_error", ("format",), input="v9", ctx={"expected": "'missionctl/mission/1'"}),
        "unsupported format 'v9'; expected 'missionctl/mission/1'",
    ),
    (err("literal_error", ctx={"expected": "'a' or 'b'"}), "7 is not one of: 'a' or 'b'"),
    (err("enum", ctx={"expected": "'idle'"}), "7 is not one of: 'idle'"),
    (
        err("union_tag_invalid", ctx={"tag": "box", "expected_tags": "'pose', 'area'"}),
        "unknown kind 'box'; expected one of 'pose', 'area'",
    ),
    (err("union_tag_not_found"), "missing field 'kind' (pose, position or area)"),
    (err("float_parsing", input="fast"), "expected a number, got 'fast'"),
    (
        err("timezone_aware", input="2026-01-01"),
        ("expected a date-time with its zone, e.g. 2026-11-28T14:00:00Z (UTC), got '2026-01-01'"),
    ),
    (
        err("string_pattern_mismatch", input="1x", ctx={"pattern": NAME_PATTERN}),
        "'1x' is not a valid name (letters, digits, '_' and '-', starting with a letter)",
    ),
    (
        err("string_pattern_mismatch", input="1x", ctx={"pattern": "^[a-z]$"}),
        "'1x' does not match ^[a-z]$",
    ),
    (err("greater_than_equal", ctx={"ge": 0}), "7 is below the minimum 0"),
    (err("greater_than", ctx={"gt": 1.5}), "7 is below the minimum 1.5"),
    (err("less_than_equal", ctx={"le": 5}), "7 is above the maximum 5"),
    (err("less_than", ctx={"lt": 2}), "7 is above the maximum 2"),
    (
        err("too_short", ("barriers", "b1", "skills")),
        "a barrier needs skills of at least two robots",
    ),
    (
        err("too_short", ctx={"min_length": 3, "actual_length": 1}),
        "needs at least 3 items, has 1",
    ),
    (err("too_long", ctx={"max_length": 64}), "has more than 64 items or characters"),
    (err("value_error", msg="Value error, no such robot"), "no such robot"),
    (err("assertion_error", msg="as it was"), "as it was"),
]


@pytest.mark.parametrize(("error", "sentence"), SENTENCES)
def test_each_error_kind_has_its_sentence(error: Any, sentence: str) -> None:
    assert _sentence(error) == sentence


DATA = {"markers": {"m": {"kind": "pose", "x": 1}}, "tasks": {"lru1": [{"id": "a"}]}}


@pytest.mark.parametrize(
    ("loc", "path"),
    [
        (("markers", "m", "pose", "x"), ("markers", "m", "x")),  # the union's tag dropped
        (("tasks", "lru1", 0, "id"), ("tasks", "lru1", 0, "id")),
        (("tasks", "lru1", 3, "id"), ("tasks", "lru1")),  # no such item
        (("tasks", "[key]"), ("tasks",)),  # about the key itself
        (("tasks", "lru1", 0, "function-after[check()]", "id"), ("tasks", "lru1", 0, "id")),
        ((), ()),
    ],
)
def test_locations_follow_the_data(loc: tuple[Any, ...], path: tuple[Any, ...]) -> None:
    assert _clean_loc(DATA, loc) == path
