"""The mission screen's context footer: the keys that apply to the selection
first, then the few that always do (no Textual here).

Which actions come first depends on what is selected — an idle skill is
edited and synchronized, a failed one retried, a running robot paused — so
FIRST lists, per status of the selected skill, the actions most likely
wanted next, and REST the others; those that apply now (availability.why_not
is None) are shown in that order, then TAIL (find, save, palette, quit; help
is F1, and in the palette). What does not fit the terminal's width
is dropped from the end of the first part, never the tail: the palette
(ctrl+p) lists every action, with why it does not apply.
"""

from __future__ import annotations

from dataclasses import dataclass

from rich.cells import cell_len

from backend.core.model import Status
from console.state.actions import BY_NAME
from console.state.availability import Facts, why_not

# the mission screen's actions, most likely next first, by the selected skill's status
# (None: no skill selected); the rest follow in REST's order
SKILL = ("edit", "duplicate", "add")
ROBOT = ("run", "pause", "stop")
FIRST: dict[Status | None, tuple[str, ...]] = {
    Status.IDLE: ("edit", "sync", "add", "duplicate", "delete", "mark", "barrier", "move_up"),
    Status.IDLE_SYNCHRONIZED: ("unsync", "run", *SKILL),
    Status.RUNNING: ("pause", "stop", *SKILL),
    Status.PAUSED: ("run", "stop", "reset", *SKILL),
    Status.SYNCHWAITING: ("stop", "unbarrier", *SKILL),
    Status.FAILURE: ("retry", "retry_edit", "run", "unsync", *SKILL),
    Status.SUCCESS: SKILL,
    None: ("add", *ROBOT),
}
REST = (
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
KEY_GLYPHS = {
    "enter": "⏎",
    "space": "␣",
    "slash": "/",
    "escape": "esc",
    "question_mark": "?",
    "delete": "del",
    "full_stop": ".",
    "comma": ",",
    "left_curly_bracket": "{",
    "right_curly_bracket": "}",
}


@dataclass(frozen=True)
class FooterKey:
    action: str  # the action's name (for a click)
    key: str  # as shown: "s", "⏎", "^s"
    label: str


# always shown, at the end: (action, key, label)
TAIL = (
    FooterKey("search", "/", "Find"),
    FooterKey("save", "^s", "Save"),
    FooterKey("command_palette", "^p", "All keys"),
    FooterKey("quit", "^q", "Quit"),
)


def key_text(keys: str) -> str:
    """The shortest way to show an action's keys: 'enter,e' -> '⏎',
    'shift+up,K' -> 'K', 'ctrl+s' -> '^s'."""
    shown = []
    for k in (x.strip() for x in keys.split(",") if x.strip()):
        k = KEY_GLYPHS.get(k, k)
        if k.startswith("ctrl+"):
            k = "^" + k.removeprefix("ctrl+")
        shown.append(k)
    return min(shown, key=cell_len) if shown else ""


def help_keys(keys: str) -> str:
    """An action's keys for the help screen: 'enter / e', '/' (not 'slash')."""
    names = {"slash": "/", "question_mark": "?"}
    return " / ".join(names.get(k.strip(), k.strip()) for k in keys.split(",") if k.strip())


def context_keys(
    facts: Facts,
    robot: str | None,
    skill_id: str | None,
    marks: list[str],
    keys: dict[str, str] | None = None,
) -> list[FooterKey]:
    """Every action that applies to the selection now, most likely first
    (`keys`: action -> its key(s) with the user's keymap; else the table's)."""
    keys = keys or {}
    found = facts.find(skill_id)
    first = FIRST[found[2].status if found else None]
    out: list[FooterKey] = []
    for name in dict.fromkeys((*first, *REST)):
        a = BY_NAME.get(name)
        if a is None or why_not(facts, name, robot, skill_id, marks) is not None:
            continue
        out.append(FooterKey(name, key_text(keys.get(name, a.key)), SHORT.get(name, a.label)))
    return out


def fit_footer(
    first: list[FooterKey], width: int, tail: tuple[FooterKey, ...] = TAIL
) -> list[FooterKey]:
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
