"""The limits on every input: one definition, checked where input enters.

Mission and library files (`backend.files.yamlio`), protocol messages
(`backend.protocol.wire.parse`) and parameter values (`backend.core.params`,
for files and operations alike) are held to these numbers; README.md and
docs/protocol.md document them. They are far above what a real mission needs
(a 10,000-skill mission file is 2.4 MB, 282,000 YAML nodes; its JSON 3.9 MB)
and far below what would exhaust the server or make a journal unreadable
(the JSON reader gives up past 200 levels of nesting).

The stored models (mission, events) carry no limits of their own: a journal
written before a limit was lowered must still replay.

A refusal names the field path and the limit, and echoes at most `echo`
characters of the value.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

Path = tuple[str | int, ...]

MiB = 1 << 20


@dataclass(frozen=True)
class Limits:
    text: int = 10_000  # characters of one string (labels, infos, parameter values, keys)
    items: int = 100_000  # entries of one list or mapping (a robot's skill list, a list value)
    depth: int = 64  # nesting of mappings and lists in one message or file
    value_depth: int = 16  # nesting inside one parameter value (it sits in other envelopes)
    payload: int = 32 * MiB  # bytes of one protocol message
    file: int = 16 * MiB  # bytes of one mission, library or other YAML file
    yaml_nodes: int = 2_000_000  # YAML nodes of one file, an alias counted at every use
    echo: int = 40  # characters of a refused value shown in the refusal


LIMITS = Limits()


@dataclass(frozen=True)
class Exceeded:
    """Where a value breaks a limit, and a sentence saying which (without the path)."""

    path: Path
    message: str


def echo(value: str, limits: Limits = LIMITS) -> str:
    """A string for a message: quoted, at most `limits.echo` characters of it."""
    if len(value) <= limits.echo:
        return repr(value)
    return repr(value[: limits.echo]) + "…"


ELIDED = "…"  # the last segment of a path cut short by `brief`


def brief(path: Path, keep: int = 12) -> Path:
    """A path short enough to print (a nesting-depth refusal's is as deep as
    the limit): its first `keep` segments, then `ELIDED`."""
    return path if len(path) <= keep else (*path[:keep], ELIDED)


def show_path(path: Path) -> str:
    """('op', 'params', 'a', 0, '…') -> 'op.params.a[0]…'."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part == ELIDED:
            out += ELIDED
        else:
            out += ("." if out else "") + part
    return out


def too_long(n: int, limits: Limits = LIMITS) -> str:
    return f"{n:,} characters, more than the limit of {limits.text:,}"


def too_many(n: int, what: str, limits: Limits = LIMITS) -> str:
    return f"{n:,} {what}, more than the limit of {limits.items:,}"


def too_deep(depth: int) -> str:
    return f"nested deeper than the limit of {depth} levels"


def too_big(n: int, limit: int, what: str) -> str:
    return f"{what} of {n:,} bytes, more than the limit of {limit:,} bytes"


def check_tree(value: Any, *, depth: int, limits: Limits = LIMITS) -> Exceeded | None:
    """The first place (in document order) where a JSON-like value breaks the
    string, item or nesting limits; None when it keeps them. `depth` counts
    mappings and lists: a flat mapping is 1 level. Iterative: any nesting is
    measured, never recursed into."""
    for path, v, level in _nodes(value):
        if not isinstance(v, str):
            found = _container_problem(path, v, level, depth, limits)
            if found is not None:
                return found
        elif len(v) > limits.text:  # strings are most nodes: checked here
            return Exceeded(path, f"{too_long(len(v), limits)} ({echo(v, limits)})")
    return None


def _container_problem(
    path: Path, v: dict[Any, Any] | list[Any], level: int, depth: int, limits: Limits
) -> Exceeded | None:
    """A mapping or list nested too deep, too long, or with a key too long."""
    if level > depth:
        return Exceeded(brief(path), too_deep(depth))
    what = "entries" if isinstance(v, dict) else "items"
    if len(v) > limits.items:
        return Exceeded(brief(path), too_many(len(v), what, limits))
    key = _long_key(v, limits) if isinstance(v, dict) else None
    if key is None:
        return None
    return Exceeded(brief(path), f"a key of {too_long(len(key), limits)}: {echo(key, limits)}")


def _long_key(v: dict[Any, Any], limits: Limits) -> str | None:
    """The first key of a mapping longer than the text limit."""
    for k in v:
        if isinstance(k, str) and len(k) > limits.text:
            return k
    return None


def _nodes(value: Any) -> Iterator[tuple[Path, Any, int]]:
    """(path, value, nesting level) of every string, mapping and list in
    `value`, parents before their children, in order."""
    stack: list[tuple[Path, Any, int]] = [((), value, 1)]
    while stack:
        path, v, level = stack.pop()
        if isinstance(v, dict):
            yield path, v, level  # a caller stopping here never has its children walked
            stack.extend(((*path, k), x, level + 1) for k, x in reversed(v.items()))
        elif isinstance(v, list | tuple):
            yield path, v, level
            stack.extend(((*path, i), x, level + 1) for i, x in reversed(list(enumerate(v))))
        elif isinstance(v, str):
            yield path, v, level


def value_problem(value: Any, limits: Limits = LIMITS) -> Exceeded | None:
    """Where a free-form value (a list or dict parameter's, say) breaks the limits."""
    if isinstance(value, int | float | bool) or value is None:
        return None  # the usual parameter: nothing to walk
    return check_tree(value, depth=limits.value_depth, limits=limits)
