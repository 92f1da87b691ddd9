"""Problems found in a file, located: `file:line:col: field.path: message`.

`Issue` is one problem; `pydantic_issues` turns a validation error into
issues with sentences an operator can act on (not pydantic's wording).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from pydantic import ValidationError
from pydantic_core import ErrorDetails

from backend.core.library import VERSION_PATTERN
from backend.core.limits import LIMITS, echo, show_path
from backend.core.model import ID_PATTERN, NAME_PATTERN
from backend.files import yamlio

Path = tuple[str | int, ...]


@dataclass
class Issue:
    file: str
    path: Path
    message: str
    line: int = 1
    col: int = 1

    def __str__(self) -> str:
        where = show_path(self.path)
        field = f"{where}: " if where else ""
        return f"{self.file}:{self.line}:{self.col}: {field}{self.message}"


class FileProblems(Exception):
    """A file could not be loaded; `issues` says every reason."""

    def __init__(self, issues: list[Issue]):
        super().__init__("\n".join(str(i) for i in issues))
        self.issues = issues


# -- pydantic errors as sentences -------------------------------------------


def _clean_loc(data: Any, loc: tuple[str | int, ...]) -> Path:
    """Map a pydantic error location onto the data: drop the segments pydantic
    adds for tagged unions (the marker kind) and validators."""
    out: list[str | int] = []
    cur = data
    for seg, nxt in zip(loc, (*loc[1:], None), strict=False):
        if seg == "[key]" or _is_union_tag(cur, seg, nxt):
            continue  # "[key]": the error is about the key itself
        step = _step(cur, seg)
        if step is not None:
            out.append(step[0])
            cur = step[1]
    return tuple(out)


def _is_union_tag(cur: Any, seg: str | int, nxt: str | int | None) -> bool:
    """`seg` is the tag pydantic puts in the location of a tagged union's
    member (the marker's kind), not a field of the data."""
    return isinstance(cur, dict) and nxt is not None and cur.get("kind") == seg and nxt in cur


def _step(cur: Any, seg: str | int) -> tuple[str | int, Any] | None:
    """The path segment `seg` is in the data under `cur`, and the data below
    it; None for a segment pydantic adds (a validator's)."""
    if isinstance(cur, dict):
        if seg in cur:
            return (seg if isinstance(seg, str) else str(seg)), cur[seg]  # a key, not an index
        if isinstance(seg, str) and not seg.startswith("function-"):
            return seg, None  # a missing field: nothing below it exists
        return None
    if isinstance(cur, list) and isinstance(seg, int) and 0 <= seg < len(cur):
        return seg, cur[seg]
    return None


_EXPECTED = {
    "float_parsing": "a number",
    "float_type": "a number",
    "int_parsing": "an integer",
    "int_type": "an integer",
    "int_from_float": "an integer",
    "bool_parsing": "true or false",
    "bool_type": "true or false",
    "string_type": "a string",
    "dict_type": "a mapping",
    "model_type": "a mapping",
    "list_type": "a list",
    "datetime_parsing": "an ISO date-time",
    "datetime_type": "an ISO date-time",
    "datetime_from_date_parsing": "an ISO date-time",
    "timezone_aware": "a date-time with its zone, e.g. 2026-11-28T14:00:00Z (UTC)",
}

_PATTERNS = {
    NAME_PATTERN: "is not a valid name (letters, digits, '_' and '-', starting with a letter)",
    ID_PATTERN: "is not a valid skill id (letters, digits, '_', '-' and '.'; no spaces)",
    VERSION_PATTERN: "is not a valid version (MAJOR.MINOR.PATCH, e.g. 1.2.0)",
}


def _shown(value: Any) -> str:
    """A value in a sentence: at most a short prefix of it (a refused value
    may be megabytes long)."""
    if isinstance(value, str):
        return echo(value)
    if isinstance(value, datetime):  # as YAML wrote it, not its repr
        return value.isoformat()
    text = repr(value) if not isinstance(value, dict | list | tuple) or len(value) <= 6 else ""
    if text and len(text) <= LIMITS.echo:
        return text
    if isinstance(value, dict):
        return f"a mapping of {len(value):,} entries"
    if isinstance(value, list | tuple):
        return f"a list of {len(value):,} items"
    return text[: LIMITS.echo] + "…"


def _last(err: ErrorDetails) -> str | int:
    loc = err["loc"]
    return loc[-1] if loc else ""


def _value(err: ErrorDetails) -> str:
    return _shown(err.get("input"))


def _ctx(err: ErrorDetails) -> dict[str, Any]:
    return err.get("ctx", {})


def _missing(err: ErrorDetails) -> str:
    return f"missing required field '{_last(err)}'"


def _unknown_field(err: ErrorDetails) -> str:
    return f"unknown field '{_last(err)}'"


def _literal(err: ErrorDetails) -> str:
    if _last(err) == "format":
        return f"unsupported format {_value(err)}; expected {err['ctx']['expected']}"
    return _not_one_of(err)


def _not_one_of(err: ErrorDetails) -> str:
    return f"{_value(err)} is not one of: {_ctx(err).get('expected')}"


def _unknown_kind(err: ErrorDetails) -> str:
    tag, expected = err["ctx"].get("tag"), err["ctx"].get("expected_tags")
    return f"unknown kind {_shown(tag)}; expected one of {expected}"


def _no_kind(err: ErrorDetails) -> str:
    return "missing field 'kind' (pose, position or area)"


def _wrong_type(err: ErrorDetails) -> str:
    return f"expected {_EXPECTED[err['type']]}, got {_value(err)}"


def _no_match(err: ErrorDetails) -> str:
    pattern = _ctx(err).get("pattern", "")
    return f"{_value(err)} " + _PATTERNS.get(pattern, f"does not match {pattern}")


def _below(err: ErrorDetails) -> str:
    ctx = _ctx(err)
    return f"{_value(err)} is below the minimum {ctx.get('ge', ctx.get('gt'))}"


def _above(err: ErrorDetails) -> str:
    ctx = _ctx(err)
    return f"{_value(err)} is above the maximum {ctx.get('le', ctx.get('lt'))}"


def _too_short(err: ErrorDetails) -> str:
    loc = err["loc"]
    if len(loc) >= 3 and loc[0] == "barriers" and loc[-1] == "skills":
        return "a barrier needs skills of at least two robots"
    ctx = _ctx(err)
    return f"needs at least {ctx.get('min_length')} items, has {ctx.get('actual_length')}"


def _too_long(err: ErrorDetails) -> str:
    return f"has more than {_ctx(err).get('max_length')} items or characters"


def _own_words(err: ErrorDetails) -> str:
    """A validator's own message, without pydantic's prefix."""
    return err["msg"].removeprefix("Value error, ")


# pydantic error type -> the sentence saying it (others: the error's message)
_PHRASES: dict[str, Callable[[ErrorDetails], str]] = {
    "missing": _missing,
    "extra_forbidden": _unknown_field,
    "literal_error": _literal,
    "enum": _not_one_of,
    "union_tag_invalid": _unknown_kind,
    "union_tag_not_found": _no_kind,
    **dict.fromkeys(_EXPECTED, _wrong_type),
    "string_pattern_mismatch": _no_match,
    "greater_than_equal": _below,
    "greater_than": _below,
    "less_than_equal": _above,
    "less_than": _above,
    "too_short": _too_short,
    "too_long": _too_long,
}


def _sentence(err: ErrorDetails) -> str:
    return _PHRASES.get(err["type"], _own_words)(err)


def pydantic_issues(file: str, doc: yamlio.YamlDoc, exc: ValidationError) -> list[Issue]:
    out = []
    for err in exc.errors():
        path = _clean_loc(doc.data, err["loc"])
        line, col = doc.mark(path)
        out.append(Issue(file, path, _sentence(err), line, col))
    return out


def duplicate_issues(file: str, doc: yamlio.YamlDoc) -> list[Issue]:
    return [
        Issue(file, p, "duplicate key: the later entry would silently replace the first", ln, c)
        for p, ln, c in doc.duplicates
    ]


def located(file: str, doc: yamlio.YamlDoc | None, path: Path, message: str) -> Issue:
    line, col = doc.mark(path) if doc else (1, 1)
    return Issue(file, path, message, line, col)
