"""Every key the console names to a person comes from the actions table (issue 27).

Hints, status lines, notifications, buttons, footers and the help write keys
through `KeyNames` (console/state/keys.py): the table's default, or the user's
keymap. This test reads every string literal of the console and fails on a key
name written by hand. What it lets through, and why:

- the table itself and the module that writes its keys (actions.py, keys.py);
- docstrings (for programmers, not shown);
- key *specifications*, not words: the key of a hidden `Binding(..., show=False)`
  (the widgets' own cursor keys, listed in the help's fixed keys), the name of a
  synthesized `events.Key`, a binding looked up by key (`_check_bindings`), and
  comparisons with or methods of a key event's `.key`;
- ALLOWED below: literal by literal, each with its reason (and an entry that no
  longer matches anything fails, so the list cannot rot).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from console.state.actions import ACTIONS, BY_ID, REVIEW_ACTIONS
from console.state.keys import KeyNames, key_text, say_key

CONSOLE = Path(__file__).resolve().parents[2] / "console"
SOURCE_OF_KEYS = {"state/actions.py", "state/keys.py"}

KEY_NAME = re.compile(
    r"""
      (?<![\w.])(?:ctrl|shift|alt)\+\w        # ctrl+s, shift+up
    | (?<![\w^])\^[a-z](?![\w])               # ^s
    | (?<![\w.])[Ff](?:1[0-2]|[1-9])(?!\w|\.\w)  # F2, f2 (not f2.yaml)
    | (?<![\w.-])(?:enter|escape|esc|tab|backspace|space)(?![\w-])  # named keys
    | [⏎␣]                                    # their glyphs
    | (?<=\s)\([a-zA-Z]\)                      # a button's '(y)'
    | (?:^|[\s(·])[a-zA-Z](?:/[a-zA-Z])?:\s    # 'r: retry', 'f: next robot'
    """,
    re.VERBOSE,
)

# (file under console/, the literal): why a key name may be written there by hand
ALLOWED: dict[tuple[str, str], str] = {
    (
        "config.py",
        '{…}: keymap.{…}: expected keys as a string, like "ctrl+s"',
    ): "an example of the keymap's syntax, not a key to press",
    (
        "web.py",
        "missionctl web: serving the console as {…} on http://{…}:{…} for the server at {…}; "
        "ctrl+c stops",
    ): "the shell's interrupt for a command-line server, no console action",
}


def _docstrings(tree: ast.AST) -> set[int]:
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                out.add(id(body[0].value))
    return out


def _call_name(call: ast.Call) -> str:
    f = call.func
    return f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""


def _key_specs(tree: ast.AST) -> set[int]:
    """String nodes that specify a key rather than name one to a person."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and node.args:
            name = _call_name(node)
            hidden = any(
                k.arg == "show" and isinstance(k.value, ast.Constant) and k.value.value is False
                for k in node.keywords
            )
            if name in ("Key", "_check_bindings") or (name == "Binding" and hidden):
                out.add(id(node.args[0]))
            f = node.func
            if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Attribute):
                if f.value.attr == "key":  # event.key.startswith("alt+")
                    out.update(id(a) for a in node.args)
        if isinstance(node, ast.Compare):
            sides = [node.left, *node.comparators]
            if any(isinstance(x, ast.Attribute) and x.attr == "key" for x in sides):
                for x in ast.walk(node):
                    out.add(id(x))
    return out


def _literals(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skip = _docstrings(tree) | _key_specs(tree)
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.JoinedStr) and id(node) not in skip:
            text = "".join(v.value if isinstance(v, ast.Constant) else "{…}" for v in node.values)
            out.append((node.lineno, text))
            skip.update(id(v) for v in node.values)
        elif (
            isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skip
        ):
            out.append((node.lineno, node.value))
    return out


def _hand_written() -> tuple[list[str], set[tuple[str, str]]]:
    found, used = [], set()
    for path in sorted(CONSOLE.rglob("*.py")):
        rel = path.relative_to(CONSOLE).as_posix()
        if rel in SOURCE_OF_KEYS:
            continue
        for line, text in _literals(path):
            if not KEY_NAME.search(text):
                continue
            if (rel, text) in ALLOWED:
                used.add((rel, text))
                continue
            found.append(f"console/{rel}:{line}: {text!r}")
    return found, used


def test_no_key_name_is_written_by_hand_outside_the_actions_table():
    found, used = _hand_written()
    assert not found, (
        "key names written by hand (write them with KeyNames from the actions table, "
        "console/state/keys.py):\n" + "\n".join(found)
    )
    assert used == set(ALLOWED), f"allowed but no longer there: {set(ALLOWED) - used}"


@pytest.mark.parametrize(
    "text",
    [
        "then ctrl+s",
        "(F6)",
        "press F6.",
        "^s Save",
        "enter: ok",
        "esc",
        "⏎ Apply",
        "Yes (y)",
        "r: retry",
    ],
)
def test_the_scan_sees_key_names(text):
    assert KEY_NAME.search(text)


@pytest.mark.parametrize("text", ["entered", "the tablet", "ROI-east", "f2.yaml", "workspace"])
def test_the_scan_leaves_words_alone(text):
    assert not KEY_NAME.search(text)


def test_keys_are_written_from_the_table_with_the_users_keymap():
    keys = KeyNames()
    assert keys.say("mission.save") == "ctrl+s" and keys.short("mission.save") == "^s"
    assert keys.say("app.show_alerts") == "F6" and keys.all("app.help") == "F1 / ?"
    assert keys.say("dialog.previous", "dialog.next") == "↑↓"
    assert (
        keys.hint(("dialog.ok", "ok"), ("dialog.cancel", "cancel")) == "enter: ok · escape: cancel"
    )
    mine = KeyNames({"editor.apply": "ctrl+j", "app.show_alerts": "f9,9"})
    assert mine.say("editor.apply") == "ctrl+j" and mine.say("app.show_alerts") == "F9"
    assert key_text("enter,e") == "⏎" and say_key("slash") == "/"
    with pytest.raises(KeyError):
        keys.say("mission.no_such_action")
    assert len(BY_ID) == len(ACTIONS) + len(REVIEW_ACTIONS)  # binding ids are unique
