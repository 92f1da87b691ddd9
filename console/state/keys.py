"""Keys as a person reads them, from the ACTIONS table and the user's keymap (no Textual here).

Every key the console names — in a hint, a status line, a notification, the
help, a button, a footer — is written by `KeyNames` from an action's binding
id ("mission.save"): the table's default (console/state/actions.py), or the
user's own keys when the keymap remaps it. Nothing else writes a key name
(tests/console/test_console_keys.py scans the console's strings for them).
"""

from __future__ import annotations

from collections.abc import Mapping

from console.state.actions import BY_ID

# how a key is written in words ('ctrl+s', 'F2', '/') ...
WORDS = {
    "slash": "/",
    "question_mark": "?",
    "plus": "+",
    "minus": "-",
    "equals_sign": "=",
    "less_than_sign": "<",
    "greater_than_sign": ">",
    "left_square_bracket": "[",
    "right_square_bracket": "]",
    "full_stop": ".",
    "comma": ",",
    "left_curly_bracket": "{",
    "right_curly_bracket": "}",
    "up": "↑",
    "down": "↓",
    "left": "←",
    "right": "→",
}
# ... and where room is short (a footer): '^s', '⏎', '␣'
GLYPHS = {
    **WORDS,
    "enter": "⏎",
    "space": "␣",
    "escape": "esc",
    "delete": "del",
}
ARROWS = frozenset("↑↓←→")


def _split(keys: str) -> list[str]:
    return [k.strip() for k in keys.split(",") if k.strip()]


def say_key(key: str) -> str:
    """One key in words: 'ctrl+s', 'enter', 'F2', '/'."""
    if len(key) >= 2 and key[0] == "f" and key[1:].isdigit():
        return key.upper()
    return WORDS.get(key, key)


def key_text(keys: str) -> str:
    """The shortest way to show an action's keys: 'enter,e' -> '⏎',
    'shift+up,K' -> 'K', 'ctrl+s' -> '^s'."""
    shown = []
    for k in _split(keys):
        k = GLYPHS.get(k, k)
        if k.startswith("ctrl+"):
            k = "^" + k.removeprefix("ctrl+")
        shown.append(k)
    return min(shown, key=len) if shown else ""  # (the glyphs are one cell wide)


def help_keys(keys: str) -> str:
    """An action's keys for the help screen: 'enter / e', 'F1 / ?'."""
    return " / ".join(say_key(k) for k in _split(keys))


class KeyNames:
    """The keys of the table's actions, with the user's keymap (binding id -> keys)."""

    def __init__(self, keymap: Mapping[str, str] | None = None) -> None:
        self.keymap = dict(keymap or {})

    def keys(self, binding_id: str) -> str:
        """The action's keys as bound: 'f2,1' (a KeyError names an id not in the table)."""
        a = BY_ID[binding_id]
        return a.key if a.fixed else self.keymap.get(binding_id, a.key)

    def say(self, *binding_ids: str) -> str:
        """The first key of each action, in words: 'ctrl+s'; two arrows read '↑↓'."""
        said = [say_key(_split(self.keys(b))[0]) for b in binding_ids]
        return ("" if all(s in ARROWS for s in said) else "/").join(said)

    def short(self, binding_id: str) -> str:
        """For a footer: '^s', '⏎'."""
        return key_text(self.keys(binding_id))

    def all(self, binding_id: str) -> str:
        """Every key of the action, for the help: 'enter / e'."""
        return help_keys(self.keys(binding_id))

    def hint(self, *parts: tuple[str | tuple[str, ...], str]) -> str:
        """'enter: ok · escape: cancel' from (binding id(s), what it does) pairs."""
        return " · ".join(
            f"{self.say(*((ids,) if isinstance(ids, str) else ids))}: {what}" for ids, what in parts
        )
