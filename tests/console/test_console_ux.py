"""What an operator tripped over at 80x24 over SSH, driven with the pilot:
degrees in the editor, stale robots, the context footer, search, duplicate,
edit and retry, the cursor after an undo, labels naming markers, escape
read as Alt, notifications, the layout (side editor, hidden robots), the
fleet filter and the alert detail."""

from __future__ import annotations

import math
from datetime import timedelta

from console_state import (
    DATA,
    MARS,
    T0,
    Builder,
    alert_received,
    engine_app,
    fleet_changed,
    inject,
    make_app,
    mars_mid_execution,
    mars_telemetry,
    screen_text,
    wait_until,
)
from textual import events

from backend.core.model import Status
from backend.core.ops import EditSkill
from backend.protocol.messages import Alert, RobotInfo
from console.screens.dialogs import ConfirmScreen, SkillSearch
from console.screens.fleet import FleetScreen

ONLINE = {"lru1": True, "lru2": True, "ardea": True, "lander": True}


def footer(app) -> str:
    return app.mission_screen.query_one("#keys").render().plain


def status_line(app) -> str:
    return str(app.mission_screen.message)


def shown(editor, field: str) -> str | None:
    """A field's text once the editor shows the skill as it is now (None
    while it rebuilds its fields)."""
    found = editor.model.find(editor.skill_id)
    if editor.loading or found is None or editor.loaded_rev != found[2].rev:
        return None
    fields = editor.query(f"#{field}")
    return fields.first().value if fields else None


# -- degrees --------------------------------------------------------------------------


async def test_angles_are_shown_and_typed_in_degrees_and_stay_radians_on_the_server():
    b = Builder(DATA / "transport.yaml")
    app, backend = engine_app(b)
    async with app.run_test(size=(120, 40)) as pilot:
        await inject(app, pilot, b, online={"lru1": True})
        screen = app.mission_screen
        screen.schedule.select("lru1-2")  # carry: from (bound) and to (typed), both poses
        ed = screen.editor
        await wait_until(
            pilot, lambda: ed.skill_id == "lru1-2" and not ed.loading, what="lru1-2 shown"
        )
        yaw = ed.query_one("#f-to-yaw")
        assert "yaw°" in screen_text(app)  # the unit in the label
        assert yaw.value == "0"
        assert ed.dirty == []  # a field left as shown is no change
        yaw.value = "90"  # a bare number: degrees, the unit shown
        await pilot.pause()
        ed.action_apply()
        await wait_until(
            pilot,
            lambda: b.mission.find("lru1-2")[2].params["to"]["yaw"] == math.pi / 2,
            what="90° applied as radians",
        )
        await wait_until(pilot, lambda: shown(ed, "f-to-yaw") == "90", what="in degrees again")
        ed.query_one("#f-to-yaw").value = "0.4rad"  # a unit says otherwise
        await pilot.pause()
        ed.action_apply()
        await wait_until(
            pilot, lambda: b.mission.find("lru1-2")[2].params["to"]["yaw"] == 0.4, what="0.4 rad"
        )
        await wait_until(pilot, lambda: shown(ed, "f-to-yaw") == "22.92", what="0.4 rad in °")
        assert ed.dirty == []  # 22.92 shown for 0.4 rad: left as it is, the value stays exact
        ed.query_one("#f-to-yaw").value = "east"
        await pilot.pause()
        assert "yaw: expected an angle in degrees" in screen_text(app)
        assert b.mission.find("lru1-2")[2].params["to"]["yaw"] == 0.4  # nothing sent


# -- stale robots -----------------------------------------------------------------------


async def test_a_robot_gone_offline_is_drawn_as_its_last_known_state():
    app = make_app()
    now = [T0]
    app.clock = lambda: now[0]
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, mars_mid_execution(), online=ONLINE, telemetry=mars_telemetry())
        text = screen_text(app)
        assert "45% ETA" in text or "45% 2m12s" in text  # live: progress and ETA
        assert "ago" not in text
        now[0] = T0 + timedelta(seconds=25)
        app.post_message(fleet_changed(RobotInfo(name="lru1", online=False, since=T0)))
        await pilot.pause()
        app.mission_screen.freshness_tick()  # (every second)
        await pilot.pause()
        lru1 = [line.split("│")[0] for line in screen_text(app).splitlines()]
        assert any(line.startswith("25s ago ≈ lru1-2") for line in lru1)  # probably now
        assert any("45% as of 25s ago" in line for line in lru1)  # progress stopped, no ETA
        assert not any("2m12s" in line or "ETA" in line for line in lru1)
        # it counts up; the robot coming back is live again
        now[0] = T0 + timedelta(seconds=40)
        app.mission_screen.freshness_tick()
        await pilot.pause()
        assert "40s ago ≈ lru1-2" in screen_text(app)
        app.post_message(fleet_changed(RobotInfo(name="lru1", online=True, since=now[0])))
        await pilot.pause()
        app.mission_screen.freshness_tick()
        await pilot.pause()
        assert "ago" not in screen_text(app).split("│")[0]


# -- the footer, search, duplicate, edit and retry, undo -----------------------------------


async def test_the_footer_shows_the_keys_of_the_selection_first():
    app = make_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        schedule = app.mission_screen.schedule
        for skill, first in (
            ("lru1-4", "⏎ Edit s Sync a Add c Dup d Delete"),  # idle
            ("lru1-2", "p Pause x Stop ⏎ Edit"),  # running
            ("lru1-3", "u Unsync ⏎ Edit"),  # queued
            ("lru2-3", "x Stop"),  # waiting at the barrier
            ("ardea-2", "T Edit+retry"),  # failed, ardea busy with ardea-3: no plain retry
        ):
            schedule.select(skill)
            await pilot.pause()
            assert footer(app).startswith(first), (skill, footer(app))
            assert footer(app).rstrip().endswith("/ Find ^s Save ^p All keys ^q Quit")
        await pilot.press("enter")  # the editor has the focus: its keys
        await pilot.pause()
        assert footer(app).startswith("⏎ Apply ^r Revert esc Close")


async def test_slash_finds_a_skill_and_jumps_to_it():
    app = make_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        await pilot.press("slash")
        await wait_until(pilot, lambda: isinstance(app.screen, SkillSearch), what="search")
        await pilot.press(*"ridge")
        await pilot.pause()
        assert "ardea-2  survey the ridge (explore)  — ardea, failure" in screen_text(app)
        assert "1 skill" in screen_text(app)
        await pilot.press("enter")
        await wait_until(
            pilot, lambda: app.mission_screen.schedule.cursor_id == "ardea-2", what="jumped"
        )
        await pilot.press("slash", *"pick the", "enter")  # typed at once, as over SSH
        await wait_until(
            pilot, lambda: app.mission_screen.schedule.cursor_id == "lru2-4", what="again"
        )


async def test_c_duplicates_a_skill_after_it():
    b = Builder(MARS)
    app, _ = engine_app(b)
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, b)
        app.mission_screen.schedule.select("lru2-5")
        await pilot.pause()
        await pilot.press("c")
        await wait_until(pilot, lambda: len(b.mission.tasks["lru2"]) == 7, what="a copy")
        ids = [s.id for s in b.mission.tasks["lru2"]]
        new = ids[ids.index("lru2-5") + 1]
        old, copy = b.mission.find("lru2-5")[2], b.mission.find(new)[2]
        assert (copy.skill, copy.label, copy.params, copy.bindings) == (
            old.skill,
            old.label,
            old.params,
            old.bindings,
        )
        await wait_until(pilot, lambda: app.mission_screen.schedule.cursor_id == new, what="on it")
        assert f"duplicated lru2-5 as {new}" in status_line(app)


async def test_edit_and_retry_opens_the_next_attempt_in_the_editor_first_in_the_plan():
    b = Builder(MARS)
    b.sync("lru1", "lru1-2")
    b.report("lru1", "lru1-1", "running")
    b.report("lru1", "lru1-1", "failure", "wheel stuck")
    app, _ = engine_app(b)
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, b)
        app.mission_screen.schedule.select("lru1-1")
        await pilot.pause()
        assert footer(app).startswith("t Retry T Edit+retry r Run")
        await pilot.press("T")  # one key: the copy, selected, in the editor
        ed = app.mission_screen.editor
        await wait_until(
            pilot,
            lambda: (
                ed.skill_id == "lru1-1.2"
                and app.focused is not None
                and ed in app.focused.ancestors_with_self
            ),
            what="the next attempt in the editor",
        )
        new = b.mission.find("lru1-1.2")[2]
        assert (new.status, new.attempt) == (Status.IDLE, 2)
        assert [s.id for s in b.mission.tasks["lru1"]][:3] == ["lru1-1", "lru1-2", "lru1-1.2"]
        assert "attempt 2" in screen_text(app)
        ed.query_one("#f-speed").value = "0.2"
        await pilot.press("enter")  # applies
        await wait_until(
            pilot, lambda: b.mission.find("lru1-1.2")[2].params["speed"] == 0.2, what="edited"
        )
        await pilot.press("escape", "s")  # back to the schedule, synchronize it
        await wait_until(
            pilot,
            lambda: b.mission.find("lru1-1.2")[2].status == Status.IDLE_SYNCHRONIZED,
            what="synchronized",
        )


async def test_undoing_a_delete_puts_the_cursor_on_the_restored_skill():
    b = Builder(MARS)
    app, _ = engine_app(b)
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, b)
        schedule = app.mission_screen.schedule
        schedule.select("lru1-3")
        await pilot.pause()
        await pilot.press("d")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="delete?")
        await pilot.press("y")
        await wait_until(pilot, lambda: b.mission.find("lru1-3") is None, what="deleted")
        await wait_until(pilot, lambda: schedule.cursor_id != "lru1-3", what="moved off")
        await pilot.press("ctrl+z")
        await wait_until(pilot, lambda: b.mission.find("lru1-3") is not None, what="restored")
        await wait_until(pilot, lambda: schedule.cursor_id == "lru1-3", what="cursor on it")


# -- editor details -------------------------------------------------------------------------


async def test_binding_another_marker_renames_a_label_that_named_the_old_one():
    b = Builder(MARS)
    app, _ = engine_app(b)
    async with app.run_test(size=(120, 40)) as pilot:
        await inject(app, pilot, b)
        app.mission_screen.schedule.select("lru1-1")  # "drive to POI-A", goal bound to POI-A
        await pilot.pause()
        ed = app.mission_screen.editor
        ed.query_one("#bind-goal").value = "POI-B"
        await pilot.pause()
        assert ed.query_one("#f-label").value == "drive to POI-B"
        ed.action_apply()
        await wait_until(
            pilot, lambda: b.mission.find("lru1-1")[2].label == "drive to POI-B", what="applied"
        )
        assert b.mission.find("lru1-1")[2].bindings == {"goal": "POI-B"}
        await wait_until(
            pilot, lambda: "applied goal, label" in status_line(app), what="said once each"
        )


async def test_escape_then_a_key_read_as_alt_key_is_escape_then_the_key():
    b = Builder(MARS)
    app, _ = engine_app(b)
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, b)
        await pilot.press("enter")  # the editor, its label field focused
        await wait_until(pilot, lambda: app.focused is not None and app.focused.id == "f-label")
        app.post_message(events.Key("alt+d", "d"))  # what "Esc d" over a laggy link reads as
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="delete?")
        assert app.mission_screen.editor.query_one("#f-label").value == "drive to POI-A"
        assert not app.mission_screen.has_class("-editing")  # escape closed the editor


async def test_applying_a_typed_value_over_a_binding_says_it_once():
    b = Builder(MARS)
    app, backend = engine_app(b)
    async with app.run_test(size=(120, 40)) as pilot:
        await inject(app, pilot, b)
        app.mission_screen.schedule.select("lru1-1")
        await pilot.pause()
        ed = app.mission_screen.editor
        ed.query_one("#bind-goal").value = "\x00typed"
        await pilot.pause()
        ed.query_one("#f-goal-x").value = "12"
        await pilot.pause()
        ed.action_apply()
        await wait_until(pilot, lambda: "applied goal" in status_line(app), what="applied")
        assert "goal, goal" not in status_line(app)
        assert backend.ops[-1] == EditSkill(
            id="lru1-1",
            params={"goal": b.mission.find("lru1-1")[2].params["goal"]},
            bindings={"goal": None},
        )


# -- notifications ----------------------------------------------------------------------------


async def test_notifications_one_per_situation_at_most_three_without_paths():
    app = make_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, Builder(MARS))
        app.notify("first", title="Refused: sync lru1")
        app.notify("again", title="Refused: sync lru1")  # the same situation: one toast
        await pilot.pause()
        shown = list(app._notifications)
        assert [(n.title, n.message) for n in shown] == [("Refused: sync lru1", "again (×2)")]
        for i in range(4):
            app.notify(f"log at /tmp/missionctl-demo-x/sim.log ({i})", title=f"Problem {i}")
        await pilot.pause()
        shown = list(app._notifications)
        assert len(shown) == 3
        assert shown[0].title == "Notifications folded" and shown[0].message.startswith("3 more")
        assert [n.title for n in shown[1:]] == ["Problem 2", "Problem 3"]
        assert shown[-1].message == "log at …/sim.log (3)"


# -- layout ------------------------------------------------------------------------------


async def test_at_80_columns_every_robot_fits_and_the_editor_opens_beside_the_schedule():
    app = make_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        screen = app.mission_screen
        assert screen.schedule.hidden_robots() == (0, 0)
        head = screen_text(app).splitlines()[1]
        assert all(r in head for r in ("lru1", "lru2", "ardea", "lander"))
        screen.schedule.select("lru2-5")
        await pilot.pause()
        await pilot.press("enter")
        await wait_until(pilot, lambda: screen.editor.display and screen.has_class("-editing"))
        await pilot.pause()
        text = screen_text(app)
        assert screen.schedule.display and screen.schedule.size.width >= 36  # beside, not instead
        assert "lru2-5  drive_to on lru2" in text
        assert "+2 robots →" in text  # the columns off screen are said, not just scrolled
        await pilot.press("escape")
        await wait_until(pilot, lambda: not screen.has_class("-editing"), what="closed")


async def test_at_120x40_the_side_editor_leaves_room_for_every_robot():
    app = make_app()
    async with app.run_test(size=(120, 40)) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        screen = app.mission_screen
        screen.schedule.select("lru2-5")
        await pilot.pause()
        assert screen.editor.display and screen.editor.size.width <= 50
        assert screen.schedule.hidden_robots() == (0, 0)


async def test_labels_are_cut_in_the_middle_and_whole_in_the_editor():
    app = make_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        text = screen_text(app)
        assert "explore…ast plain" in text  # "explore east plain": both ends
        app.mission_screen.schedule.select("lru1-2")
        await pilot.press("enter")
        await wait_until(pilot, lambda: app.mission_screen.editor.query("#f-label"))
        assert app.mission_screen.editor.query_one("#f-label").value == "explore east plain"


# -- part-2 screens ---------------------------------------------------------------------------


async def test_fleet_filter_examples_and_typing_after_escape():
    from console_state import mars_fleet_with_manifests, state_loaded

    b = Builder(MARS)
    app = make_app()
    async with app.run_test(size=(80, 24)) as pilot:
        app.post_message(state_loaded(b.snapshot(), b.library, mars_fleet_with_manifests()))
        await pilot.pause()
        await pilot.press("f4")
        await wait_until(pilot, lambda: isinstance(app.screen, FleetScreen), what="fleet")
        field = app.screen.query_one("#filter")
        assert "module:" in field.placeholder and "prop:" in field.placeholder
        await pilot.press(*"lru")
        await pilot.press("escape")  # back to the list
        await pilot.press(*"arm")  # a new word, not "lruarm"
        await wait_until(pilot, lambda: field.value == "lru arm", what="two words")
        assert app.screen.shown == ["lru2"]


async def test_the_alert_list_shows_the_selected_alert_in_full():
    app = make_app()
    long = (
        "lru1: lru1-1 failure: no route from (4.0, 3.0) to (900.0, 18.0): the goal "
        "(900.0, 18.0) is outside the site (x -160..160, y -160..160)"
    )
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, Builder(MARS))
        failed = Alert(
            id=1, level="error", kind="failure", robot="lru1", skill="lru1-1", message=long, at=T0
        )
        app.post_message(alert_received(failed))
        await wait_until(pilot, lambda: app.alerts.alerts, what="the alert")
        app.clear_notifications()  # (the toast would cover the list at 80x24)
        await pilot.press("f6")
        await pilot.pause()
        await pilot.pause()
        text = " ".join(screen_text(app).split())
        assert "is outside the site (x -160..160, y -160..160)" in text  # the whole text
        assert "lru1 · lru1-1" in text
