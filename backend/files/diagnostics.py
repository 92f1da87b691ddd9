"""Problems found in a file, located: `file:line:col: field.path: message`.

`Issue` is one problem; `pydantic_issues` turns a validation error into
issues with sentences an operator can act on (not pydantic's wording).
"""

from __future__ import annotations

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
    for i, seg in enumerate(loc):
        nxt = loc[i + 1] if i + 1 < len(loc) else None
        if seg == "[key]":
            continue  # the error is about the key itself
        if isinstance(cur, dict) and cur.get("kind") == seg and nxt is not None and nxt in cur:
            continue  # union tag
        if isinstance(cur, dict) and seg in cur:
            out.append(seg if isinstance(seg, str) else str(seg))  # a key, not an index
            cur = cur[seg]
        elif isinstance(cur, list) and isinstance(seg, int) and 0 <= seg < len(cur):
            out.append(seg)
            cur = cur[seg]
        elif isinstance(cur, dict) and isinstance(seg, str) and not seg.startswith("function-"):
            out.append(seg)  # a missing field: nothing below it exists
            cur = None
    return tuple(out)


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


def _sentence(err: ErrorDetails) -> str:
    t = err["type"]
    loc = err["loc"]
    last = loc[-1] if loc else ""
    if t == "missing":
        return f"missing required field '{last}'"
    if t == "extra_forbidden":
        return f"unknown field '{last}'"
    if t == "literal_error" and last == "format":
        return f"unsupported format {_shown(err.get('input'))}; expected {err['ctx']['expected']}"
    if t == "union_tag_invalid":
        tag, expected = err["ctx"].get("tag"), err["ctx"].get("expected_tags")
        return f"unknown kind {_shown(tag)}; expected one of {expected}"
    if t == "union_tag_not_found":
        return "missing field 'kind' (pose, position or area)"
    value = _shown(err.get("input"))
    ctx = err.get("ctx", {})
    if t in _EXPECTED:
        return f"expected {_EXPECTED[t]}, got {value}"
    if t == "string_pattern_mismatch":
        pattern = ctx.get("pattern", "")
        return f"{value} " + _PATTERNS.get(pattern, f"does not match {pattern}")
    if t in ("enum", "literal_error"):
        return f"{value} is not one of: {ctx.get('expected')}"
    if t in ("greater_than_equal", "greater_than"):
        bound = ctx.get("ge", ctx.get("gt"))
        return f"{value} is below the minimum {bound}"
    if t in ("less_than_equal", "less_than"):
        bound = ctx.get("le", ctx.get("lt"))
        return f"{value} is above the maximum {bound}"
    if t == "too_short":
        if len(loc) >= 3 and loc[0] == "barriers" and loc[-1] == "skills":
            return "a barrier needs skills of at least two robots"
        return f"needs at least {ctx.get('min_length')} items, has {ctx.get('actual_length')}"
    if t == "too_long":
        return f"has more than {ctx.get('max_length')} items or characters"
    msg: str = err["msg"]
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, ") :]
    return msg


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
