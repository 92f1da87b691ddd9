"""console.widgets.select.SafeSelect: a Select removed while its value changes (the
parameter editor rebuilding during a resync) must not end the console."""

from __future__ import annotations

import pytest
from textual.app import App, ComposeResult
from textual.css.query import NoMatches
from textual.widgets import Select
from textual.widgets._select import SelectOverlay

from console.widgets.select import SafeSelect


class OneSelect(App):
    def __init__(self, cls: type[Select]):
        super().__init__()
        self.cls = cls

    def compose(self) -> ComposeResult:
        yield self.cls([("pose", "pose"), ("area", "area")], value="pose", allow_blank=False)


async def test_textual_select_fails_when_its_overlay_is_gone_first():
    # why SafeSelect exists; if Textual fixes this, SafeSelect can go
    app = OneSelect(Select)
    async with app.run_test():
        select = app.query_one(Select)
        await select.query_one(SelectOverlay).remove()
        with pytest.raises(NoMatches):
            select.value = "area"


async def test_safe_select_takes_a_value_while_being_torn_down():
    app = OneSelect(SafeSelect)
    async with app.run_test() as pilot:
        select = app.query_one(SafeSelect)
        await select.query_one(SelectOverlay).remove()
        select.value = "area"
        await pilot.pause()
        assert select.value == "area" and app.is_running
