"""The mission screen's context footer: the keys that apply to the selection
first, then the few that always do (no Textual here).

Which actions come first depends on what is selected — an idle skill is
edited and synchronized, a failed one retried, a running robot paused — so
FIRST lists, per status of the selected skill, the actions most likely
wanted next, and REST the others; those that apply now (availability.why_not
is None) are shown in that order, then TAIL (find, save, palette, quit; help
is in the palette). What does not fit the terminal's width is dropped from
the end of the first part, never the tail: the palette lists every action,
with why it does not apply. Keys are written from the actions table, with
the user's keymap (console/state/keys.py).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from rich.cells import cell_len

from backend.core.model import Status
from console.state.actions import BY_ID, BY_NAME
from console.state.availability import Facts, why_not
from console.state.keys import KeyNames

# the mission screen's actions, most likely next first, by the selected skill's status
# (None: no skill selected); the rest follow in REST's order
SKILL = ("edit", "duplicate", "add")
ROBOT = ("run", "pause", "stop")
FIRST: dict[Status | None, tuple[str, ...]] = {
    Status.IDLE: (
        "cancel",
        "edit",
        "sync",
        "add",
        "duplicate",
        "delete",
        "mark",
        "barrier",
        "move_up",
    ),
    Status.IDLE_SYNCHRONIZED: ("cancel", "unsync", "run", *SKILL),
    Status.RUNNING: ("pause", "stop", *SKILL),
    Status.PAUSED: ("run", "stop", "reset", *SKILL),
    Status.SYNCHWAITING: ("stop", "unbarrier", *SKILL),
    Status.FAILURE: ("retry", "retry_edit", "run", "unsync", *SKILL),
    Status.SUCCESS: SKILL,
    None: ("add", *ROBOT),
}
REST = (
    "cancel",
    "edit",
    "sync",
    "unsync",
    *ROBOT,
    "add",
    "duplicate",
    "delete",
    "barrier",
    "mark",
    "move_up",
    "move_down",
    "unbarrier",
    "reset",
    "undo",
    "run_all",
    "pause_all",
    "stop_all",
    "reset_all",
)
# short footer labels where the table's are long (the palette and help keep the full ones)
SHORT = {"retry_edit": "Edit+retry", "duplicate": "Dup", "unbarrier": "Unbar"}


@dataclass(frozen=True)
class FooterKey:
    action: str  # the action's name (for a click)
    key: str  # as shown: "s", "⏎", "^s"
    label: str


# always shown, at the end: (binding id, label)
TAIL = (
    ("mission.search", "Find"),
    ("mission.save", "Save"),
    ("app.command_palette", "All keys"),
    ("app.quit", "Quit"),
)
# the footer while the parameter editor has the focus (before the tail)
EDITOR = ("editor.apply", "editor.revert", "editor.leave")


def footer_keys(ids: Iterable[str | tuple[str, str]], keys: KeyNames) -> list[FooterKey]:
    """Footer entries for binding ids (or (binding id, label) pairs)."""
    out = []
    for item in ids:
        bid, label = item if isinstance(item, tuple) else (item, BY_ID[item].label)
        out.append(FooterKey(BY_ID[bid].name, keys.short(bid), label))
    return out


def tail_keys(keys: KeyNames) -> list[FooterKey]:
    return footer_keys(TAIL, keys)


def context_keys(
    facts: Facts,
    robot: str | None,
    skill_id: str | None,
    marks: list[str],
    keys: KeyNames | None = None,
) -> list[FooterKey]:
    """Every action that applies to the selection now, most likely first
    (`keys`: with the user's keymap; else the table's)."""
    keys = keys or KeyNames()
    found = facts.find(skill_id)
    first = FIRST[found[2].status if found else None]
    out: list[FooterKey] = []
    for name in dict.fromkeys((*first, *REST)):
        a = BY_NAME.get(name)
        if a is None or why_not(facts, name, robot, skill_id, marks) is not None:
            continue
        out.append(FooterKey(name, keys.short(a.binding_id), SHORT.get(name, a.label)))
    return out


def fit_footer(first: list[FooterKey], width: int, tail: list[FooterKey]) -> list[FooterKey]:
    """As many of `first` as fit before `tail` in `width` cells (each key
    takes its text, a space, its label and a gap of one)."""

    def size(k: FooterKey) -> int:
        return cell_len(k.key) + 1 + cell_len(k.label) + 1

    room = width - sum(size(k) for k in tail)
    shown: list[FooterKey] = []
    for k in first:
        if size(k) > room:
            break
        shown.append(k)
        room -= size(k)
    return shown + list(tail)
