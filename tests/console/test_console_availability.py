"""The availability rules sit beside the actions table: one rule per mission
action that depends on the selection; the others always apply (the server decides)."""

from __future__ import annotations

from console.state.actions import BY_NAME
from console.state.availability import OFFLINE_OK, READ_ONLY_OK, RULES


def test_every_rule_belongs_to_an_action_of_the_mission_screen():
    assert set(RULES) <= set(BY_NAME)
    assert set(BY_NAME) - set(RULES) == {
        "undo",
        "redo",
        "save",
        "load",
        "toggle_static",
        "search",
    }


def test_what_applies_offline_also_applies_read_only():
    assert OFFLINE_OK <= READ_ONLY_OK
