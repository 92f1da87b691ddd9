"""Input that cannot misfire (issue 27): keys typed while a dialog, picker,
prompt or the editor opens go to it; a key that commands a robot acts only on
a press on the schedule; editor fields keep every key of a burst; enter
applies from every field and the focus stays there; ctrl+a selects a text box.

A burst is posted as the terminal driver posts keys: all at once, before the
app has handled the first (`pilot.press` waits after each key, which hides
the problem)."""

from __future__ import annotations

import pytest
from console_state import (
    MARS,
    TUTORIAL,
    Builder,
    applied_batch,
    engine_app,
    inject,
    screen_text,
    wait_until,
)
from textual import events
from textual.widgets import Select, Switch, TextArea

from backend.core.ops import AddSkill, EditSkill, Sync
from console.bindings import mission_keys
from console.screens.dialogs import SkillPicker
from console.state.actions import ACTIONS
from console.state.keys import KeyNames
from console.widgets.editor.inputs import TYPED

ONLINE = {"lru1": True, "lru2": True}
CHARS = {"space": " "}


def burst(app, keys) -> None:
    """Keys as a terminal delivers a burst: posted together, handled later."""
    for k in keys:
        app.post_message(events.Key(k, CHARS.get(k, k if len(k) == 1 else None)))


def typed(text: str) -> list[str]:
    return ["space" if c == " " else c for c in text]


def rebuilt(editor, sid: str) -> bool:
    """The editor shows `sid` as it is now (its fields rebuilt after an apply)."""
    return not editor.loading and editor.loaded_rev == editor.model.find(sid)[2].rev


async def settled(app, pilot) -> None:
    """Until the burst is handled: nothing held, the workers that opened things done."""
    await wait_until(pilot, lambda: not app.typeahead.holding, what="keys released")
    await pilot.pause()
    await pilot.pause()


async def test_a_then_science_typed_fast_goes_to_the_picker():
    b = Builder(TUTORIAL)
    app, backend = engine_app(b)
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, b, online=ONLINE)
        app.mission_screen.schedule.select("lru1-2")
        await pilot.pause()
        burst(app, ["a", *typed("science")])  # 's' syncs and 'c' duplicates on the schedule
        await settled(app, pilot)
        assert backend.ops == []
        assert isinstance(app.screen, SkillPicker)
        assert app.screen.query_one("#filter").value == "science"
        burst(app, ["enter"])
        await wait_until(pilot, lambda: backend.ops, what="the picker's add")
        [op] = backend.ops
        assert isinstance(op, AddSkill) and op.skill == "take_science_image"
        apply = KeyNames().say("editor.apply")  # the hint names the editor's key, not save's
        await wait_until(
            pilot,
            lambda: f"{apply} in a field applies them" in str(app.mission_screen.message),
            what="the hint after the add",
        )


def _openers() -> list[str]:
    """The schedule's and the app's keys that open something (the actions table)."""
    keys = KeyNames()
    return [
        keys.keys(a.binding_id).split(",")[0]
        for a in ACTIONS
        if a.opens and a.scope in ("mission", "app")
    ]


@pytest.mark.parametrize("key", _openers())
async def test_every_key_that_opens_something_keeps_the_keys_typed_after_it(key):
    b = Builder(TUTORIAL)
    b.sync("lru1", "lru1-1")  # something to reset
    b.engine.submit(Sync(robot="lru2", through="lru2-1"))  # a command to cancel, pending
    app, backend = engine_app(b)
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, b, online=ONLINE)
        edit = b.engine.submit(EditSkill(id="lru2-2", label="unsaved"))  # quitting asks first
        app.post_message(applied_batch(edit.batch()))
        screen = app.mission_screen
        action = mission_keys(KeyNames()).get(key)
        # an idle skill after a queued one; or one the pending command locks
        screen.schedule.select("lru2-1" if action == "cancel" else "lru1-2")
        await pilot.pause()
        assert action is None or screen.why_disabled(action) is None  # it opens now
        # sync, run, stop, unsync, duplicate, delete, barrier on the schedule
        burst(app, [key, *"srxucdb"])
        await settled(app, pilot)
        assert backend.ops == [], f"{key}: {backend.ops}"
        assert app.return_code is None  # still running


async def test_a_robot_command_acts_only_on_a_press_on_the_schedule():
    b = Builder(TUTORIAL)
    app, backend = engine_app(b)
    async with app.run_test(size=(120, 40)) as pilot:
        await inject(app, pilot, b, online=ONLINE)
        screen = app.mission_screen
        screen.schedule.select("lru2-1")
        await pilot.pause()
        screen.editor.query_one("#bind-goal", Select).focus()  # a choice: 's' is not typed
        await pilot.pause()
        burst(app, ["s"])
        await wait_until(pilot, lambda: "press on the schedule" in str(screen.message), what="why")
        assert backend.ops == []
        screen.schedule.focus()
        await pilot.pause()
        burst(app, ["s"])
        await wait_until(pilot, lambda: backend.ops, what="the sync")
        assert backend.ops[0].op == "sync"


async def test_thirty_backspaces_and_twenty_characters_in_one_burst_reach_the_field():
    b = Builder(MARS)
    app, backend = engine_app(b)
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, b, online=ONLINE)
        screen = app.mission_screen
        screen.schedule.select("lru1-2")  # explore east plain: max_duration 240
        await pilot.pause()
        burst(app, ["enter"])  # into the editor (its label first)
        await settled(app, pilot)
        assert app.focused.id == "f-label"
        burst(app, ["x", "end", *["backspace"] * 30, *typed("explore SE quadrant!")])
        await settled(app, pilot)
        assert screen.editor.query_one("#f-label").value == "explore SE quadrant!"
        field = screen.editor.query_one("#f-max_duration")
        field.focus()
        await pilot.pause()
        burst(app, ["end", "backspace", "backspace", "backspace", "4", "0", "0", "enter"])
        await wait_until(
            pilot,
            lambda: b.mission.find("lru1-2")[2].params.get("max_duration") == 400,
            what="max_duration applied",
        )
        assert b.mission.find("lru1-2")[2].label == "explore SE quadrant!"
        await wait_until(pilot, lambda: rebuilt(screen.editor, "lru1-2"), what="reloaded")
        assert app.focused.id == "f-max_duration"  # the focus stays in the field after apply


async def test_enter_applies_from_a_closed_choice_and_a_switch():
    b = Builder(TUTORIAL)
    app, backend = engine_app(b)
    async with app.run_test(size=(120, 40)) as pilot:
        await inject(app, pilot, b, online=ONLINE)
        screen = app.mission_screen
        screen.schedule.select("lru2-1")  # goal typed: the bind choice says "typed value"
        await pilot.pause()
        choice = screen.editor.query_one("#bind-goal", Select)
        choice.value = "POI-A"
        choice.focus()
        await pilot.pause()
        burst(app, ["enter"])
        await wait_until(
            pilot,
            lambda: b.mission.find("lru2-1")[2].bindings.get("goal") == "POI-A",
            what="applied from the choice",
        )
        assert not choice.expanded  # enter did not open it again
        await wait_until(pilot, lambda: rebuilt(screen.editor, "lru2-1"), what="reloaded")
        assert app.focused.id == "bind-goal"  # the focus stays in the field after apply
        switch = screen.editor.query_one("#pf-pause_out_of_comms", Switch)
        switch.focus()
        burst(app, ["space", "enter"])
        await wait_until(
            pilot,
            lambda: b.mission.find("lru2-1")[2].policies.pause_out_of_comms,
            what="applied from the switch",
        )


async def test_ctrl_a_selects_a_whole_text_box():
    b = Builder(MARS)
    app, _ = engine_app(b)
    async with app.run_test(size=(120, 40)) as pilot:
        await inject(app, pilot, b, online=ONLINE)
        screen = app.mission_screen
        screen.schedule.select("lru1-2")  # explore: its area bound to ROI-east
        await pilot.pause()
        screen.editor.query_one("#bind-area", Select).value = TYPED  # a typed polygon
        await pilot.pause()
        box = screen.editor.query_one("#f-area", TextArea)
        box.text = "- {x: 1, y: 2}\n- {x: 3, y: 4}\n- {x: 5, y: 1}"
        box.focus()
        await pilot.pause()
        burst(app, [KeyNames().keys("editor.select_all")])
        await wait_until(pilot, lambda: box.selected_text == box.text, what="all selected")
        burst(app, ["backspace"])
        await wait_until(pilot, lambda: box.text == "", what="all deleted")
        assert "area" in screen_text(app)
