"""The editor's "Contingency" group: what the robot does on board when a
skill fails or runs out of time (policies timeout, not_after, on_failure,
on_timeout), typed as ctl takes them (backend.core.contingency)."""

from __future__ import annotations

from typing import Any

from textual.app import ComposeResult
from textual.dom import DOMNode
from textual.widgets import Input

from backend.core.contingency import (
    BRANCH_SYNTAX,
    clock_text,
    read_branch,
    read_instant,
    read_seconds,
    span_text,
    typed_branch,
)
from backend.core.model import Branch, Policies
from console.widgets.editor.fields import FieldInput

# policy -> (label, type hint), in the order the group shows them
CONTINGENCY_HINTS = {
    "timeout": ("timeout", "mission time: 10m, 1.5h; empty: none"),
    "not_after": ("not after", "mission clock: sim 2:00:00; empty: none"),
    "on_failure": ("on failure", "skip, goto:M, fallback:S+S"),
    "on_timeout": ("on timeout", "skip, goto:M, fallback:S+S"),
}
TIMES = ("timeout", "not_after")


class BranchInput(FieldInput):
    """A branch as typed; it keeps the one it shows (a fallback's parameters
    are not in the text): unchanged text gives it back whole."""

    def __init__(self, branch: Branch, **kwargs: Any):
        super().__init__(typed_branch(branch), **kwargs)
        self.original = branch

    def branch(self) -> Branch | None:
        if self.value.strip() == typed_branch(self.original):
            return self.original
        return read_branch(self.value)


# how each time is written in its field, and read back
_WRITE = {"timeout": span_text, "not_after": clock_text}  # '10m'; 'sim 2:00:00' (an instant)
_READ = {"timeout": read_seconds, "not_after": read_instant}


def time_text(name: str, p: Policies) -> str:
    """A time as typed: a timeout '10m', a deadline the instant it is: 'sim 2:00:00'."""
    value = getattr(p, name)
    return "" if value is None else _WRITE[name](value)


def contingency_input(name: str, p: Policies, disabled: bool) -> ComposeResult:
    if name in TIMES:
        yield FieldInput(
            time_text(name, p),
            id=f"pf-{name}",
            compact=True,
            disabled=disabled,
            placeholder="none",
        )
    else:
        yield BranchInput(getattr(p, name), id=f"pf-{name}", compact=True, disabled=disabled)


def read_contingency(root: DOMNode) -> tuple[dict[str, Any], dict[str, str]]:
    """The contingency fields as typed, and problems per field."""
    raw: dict[str, Any] = {}
    problems: dict[str, str] = {}
    for name in TIMES:
        seconds = _READ[name](_time_input(root, name).value)
        if isinstance(seconds, str):
            problems[name] = seconds
        else:
            raw[name] = seconds
    for name in ("on_failure", "on_timeout"):
        w = root.query_one(f"#pf-{name}", BranchInput)
        branch = w.branch()
        if branch is None:
            problems[name] = f"expected {BRANCH_SYNTAX}, got {w.value!r}"
        else:
            raw[name] = branch
    return raw, problems


def _time_input(root: DOMNode, name: str) -> Input:
    return root.query_one(f"#pf-{name}", Input)
