"""The console's screens, driven with Textual's pilot, state injected offline.

Each test asserts on what the terminal shows (robot names, skill labels,
statuses, reasons), so an app that fails to start cannot pass.
"""

from __future__ import annotations

from console_state import (
    MARS_FLEET,
    TUTORIAL,
    Builder,
    EngineBackend,
    engine_app,
    fleet_changed,
    inject,
    link_state,
    make_app,
    mars_mid_execution,
    mars_telemetry,
    screen_text,
    wait_exit,
    wait_until,
)

from backend.client.client import OperationRefused
from backend.core.model import Status
from backend.core.ops import Retry, RetryAck
from backend.protocol.messages import ErrorReply, OpReply
from backend.transport import free_port, loopback_endpoint
from console.config import ConsoleConfig
from console.screens.dialogs import HelpScreen, SkillPicker, UnreachableScreen
from console.widgets.editor.editor import ParamEditor
from console.widgets.schedule.view import ScheduleView

WIDE = (150, 42)


def shows(editor, sid: str) -> bool:
    """The editor shows `sid`, its fields built."""
    return editor.skill_id == sid and not editor.loading


def status_line(app) -> str:
    return str(app.mission_screen.message)


async def test_before_any_state_the_schedule_says_it_waits():
    app = make_app()
    async with app.run_test(size=(100, 24)) as pilot:
        await pilot.pause()
        text = screen_text(app)
        assert "no mission yet" in text
        assert "missionctl" in text


async def test_mars_mid_execution_shows_every_status_barrier_progress_and_presence():
    app = make_app()
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        text = screen_text(app)
        for robot in ("lru1", "lru2", "ardea", "lander"):
            assert robot in text
        for label in (
            "drive to POI-A",
            "explore east plain",
            "take sample box",
            "survey the ridge",
            "land on the lander",
            "recharge",
        ):
            assert label in text, label
        for glyph in ("✓", "✗", "▶", "‖", "◷", "●", "○"):
            assert glyph in text, glyph
        assert text.count("[b1]") == 2  # on both partners
        assert "45%" in text and "ETA 2m12s" in text  # running skill, from telemetry
        assert "offline 10:42:07" in text  # ardea, from the injected timestamp
        assert "bat 82%" in text and "link 90%" in text
        assert "battery below 15%" in text  # the failure's reason
        assert "b1: waiting for lru1" in text  # the waiting robot's barrier
        assert "Mars sample return" in text and "connected" in text
        # sections: the divider runs across the columns
        assert "plan" in text


async def test_cursor_selects_a_skill_and_the_editor_follows():
    app = make_app()
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        view = app.screen.query_one(ScheduleView)
        assert view.cursor_robot == "lru1" and view.cursor_id == "lru1-4"  # first of the plan
        await pilot.press("down")
        assert view.cursor_id == "lru1-5"
        await pilot.press("right")
        assert view.cursor_robot == "lru2"
        await pilot.press("home")
        assert view.cursor_id == "lru2-1"
        await pilot.pause()
        assert "lru2-1" in screen_text(app) and "pick_payload_box on lru2" in screen_text(app)


async def test_read_only_editor_says_why():
    app = make_app()
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        app.screen.query_one(ScheduleView).select("lru1-2")
        editor = app.screen.query_one(ParamEditor)
        await wait_until(pilot, lambda: shows(editor, "lru1-2"), what="lru1-2 in the editor")
        assert "read-only: lru1-2 is running on lru1" in screen_text(app)
        banner = str(app.screen.query_one("#readonly").render())
        assert banner == (
            "read-only: lru1-2 is running on lru1: only idle skills can be edited; "
            "stop the robot (the skill goes back to its queue), then unsynchronize it"
        )
        assert all(w.disabled for w in editor.query("Input, Select, Switch, TextArea"))
        app.screen.query_one(ScheduleView).select("lru1-1")
        await wait_until(pilot, lambda: shows(editor, "lru1-1"), what="lru1-1 in the editor")
        assert "finished skills are the execution log" in str(
            app.screen.query_one("#readonly").render()
        )


async def test_actions_that_do_not_apply_say_why():
    app = make_app(backend=EngineBackend(Builder()))
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        screen = app.mission_screen
        screen.schedule.select("lru1-2")  # running
        await pilot.pause()
        assert screen.why_disabled("delete")  # not in the footer
        assert "d Delete" not in screen_text(app).splitlines()[-1]
        await pilot.press("d")
        assert "only idle skills can be deleted" in status_line(app)
        await pilot.press("r")
        assert "lru1 is already executing lru1-2" in status_line(app)
        await pilot.press("u")
        assert "only queued (idle_synchronized) skills can be unsynchronized" in status_line(app)
        await pilot.press("b")
        assert "mark one idle skill on each of at least two robots" in status_line(app)
        screen.schedule.select("ardea-3")  # ardea is offline: a command waits for it
        await pilot.press("x")
        await pilot.pause()
        assert "stop ardea" in status_line(app) and "offline" not in status_line(app)


async def test_add_with_picker_then_edit_with_inline_validation_then_apply():
    b = Builder(TUTORIAL)
    app, backend = engine_app(b)
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, b, online={"lru1": True, "lru2": True})
        screen = app.mission_screen
        screen.schedule.select("lru1-2")
        await pilot.pause()
        await pilot.press("a")
        await wait_until(
            pilot, lambda: isinstance(app.screen, SkillPicker), what="the skill picker"
        )
        assert "take_science_image" in screen_text(app)
        await pilot.press("r", "e", "c", "h")
        await pilot.pause()
        assert "Return to the lander and recharge" in screen_text(app)  # descriptions shown
        await pilot.press("enter")
        await wait_until(
            pilot,
            lambda: any(s.skill == "recharge" for s in b.mission.tasks["lru1"]),
            what="the skill added",
        )
        new = b.mission.tasks["lru1"][-1]
        assert new.id == "lru1-3" and new.status == Status.IDLE
        await wait_until(
            pilot,
            lambda: (
                screen.editor.skill_id == new.id
                and app.focused is not None
                and screen.editor in app.focused.ancestors_with_self
            ),
            what="editor focused on the new skill",
        )
        field = screen.editor.query_one("#f-target_level")
        field.value = "2"
        await pilot.pause()
        assert "2.0 is above the maximum 1" in screen_text(app)  # inline, before sending
        await pilot.press("enter")  # enter in a field applies
        await pilot.pause()
        assert b.mission.find(new.id)[2].params["target_level"] == 0.95  # not sent
        field.value = "0.5"
        await pilot.pause()
        assert "above the maximum" not in screen_text(app)
        await pilot.press("enter")  # enter in a field applies
        await wait_until(
            pilot,
            lambda: b.mission.find(new.id)[2].params["target_level"] == 0.5,
            what="the edit applied",
        )
        await wait_until(
            pilot, lambda: "applied target_level" in status_line(app), what="status line"
        )


async def test_server_refusal_for_a_parameter_appears_next_to_the_field():
    class Refusing:
        async def submit(self, op, *, expected_revision=None) -> OpReply:
            raise OperationRefused(
                ErrorReply(
                    code="bad_param",
                    message="lru1, skill lru1-4 (take_science_image), parameter filter: "
                    "the camera has no such filter today",
                    robot="lru1",
                    skill="lru1-4",
                    param="filter",
                )
            )

    app = make_app(backend=Refusing())
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        screen = app.mission_screen
        screen.schedule.select("lru1-4")
        await pilot.pause()
        screen.editor.query_one("#f-label").value = "a new label"
        await pilot.pause()
        screen.editor.action_apply()
        await wait_until(
            pilot,
            lambda: "no such filter today" in screen.editor.errors.get("filter", ""),
            what="the refusal next to the field",
        )
        text = screen_text(app)
        assert "the camera has no such filter today" in text
        assert "[lru1 · lru1-4]" in status_line(app)  # robot, skill and reason
        assert "edit lru1-4 refused" in status_line(app)


async def test_barrier_from_marks_across_robots():
    b = mars_mid_execution()
    app, backend = engine_app(b)
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, b, telemetry=mars_telemetry())
        screen = app.mission_screen
        screen.schedule.select("lru1-5")
        await pilot.pause()
        await pilot.press("space")
        assert screen.why_disabled("barrier")  # one robot only
        screen.schedule.select("lru2-5")
        await pilot.pause()
        await pilot.press("space")
        assert "marked: lru1-5, lru2-5" in screen_text(app)
        await pilot.press("b")
        await wait_until(pilot, lambda: "b2" in b.mission.barriers, what="barrier b2")
        assert b.mission.barriers["b2"].skills == ["lru1-5", "lru2-5"]
        await wait_until(
            pilot, lambda: screen_text(app).count("[b2]") == 2, what="tags on both partners"
        )
        # remove it again
        await pilot.press("B")
        await wait_until(pilot, lambda: "b2" not in b.mission.barriers, what="barrier removed")


async def test_sync_unsync_delete_move_and_retry_offline():
    b = mars_mid_execution()
    app, backend = engine_app(b)
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, b, telemetry=mars_telemetry())
        screen = app.mission_screen
        screen.schedule.select("lru2-5")
        await pilot.pause()
        await pilot.press("s")
        await wait_until(
            pilot,
            lambda: b.mission.find("lru2-5")[2].status == Status.IDLE_SYNCHRONIZED,
            what="sync",
        )
        await pilot.press("u")
        await wait_until(
            pilot, lambda: b.mission.find("lru2-5")[2].status == Status.IDLE, what="unsync"
        )
        await pilot.press("shift+down")
        await wait_until(
            pilot,
            lambda: [s.id for s in b.mission.tasks["lru2"]][-1] == "lru2-5",
            what="moved down",
        )
        await pilot.press("d")
        await wait_until(pilot, lambda: "Delete lru2-5" in screen_text(app), what="confirmation")
        await pilot.press("y")
        await wait_until(pilot, lambda: b.mission.find("lru2-5") is None, what="deleted")
        # retry needs a failed skill and no active one: stop ardea's paused skill first
        b.report("ardea", "ardea-3", "idle_synchronized")
        from console_state import fleet, state_loaded

        app.post_message(state_loaded(b.snapshot(), b.library, fleet(MARS_FLEET | {"ardea": True})))
        await pilot.pause()
        screen.schedule.select("ardea-2")
        await pilot.pause()
        await pilot.press("t")
        await wait_until(pilot, lambda: b.mission.find("ardea-2.2") is not None, what="retry")
        assert b.mission.find("ardea-2.2")[2].status == Status.IDLE_SYNCHRONIZED
        await wait_until(pilot, lambda: "#2" in screen_text(app), what="attempt shown")


async def test_help_screen_lists_the_keys_and_the_legend():
    app = make_app(config=ConsoleConfig(keymap={"mission.sync": "S"}))
    async with app.run_test(size=(110, 60)) as pilot:
        await inject(app, pilot, mars_mid_execution())
        await pilot.press("f1")
        await wait_until(pilot, lambda: isinstance(app.screen, HelpScreen), what="help")
        text = screen_text(app)
        assert "Synchronization" in text and "Execution" in text
        assert "S               Sync" in text  # the remapped key
        assert "d / delete" in text
        app.screen.query_one("VerticalScroll").scroll_end(
            animate=False, immediate=True
        )  # the legend is further down
        await pilot.pause()
        end = screen_text(app)
        assert (
            "waiting at barrier" in end
            and "◷" in end
            and "mission.sync" in end
            and "unapplied changes" in end
        )
        await pilot.press("escape")
        await wait_until(pilot, lambda: not isinstance(app.screen, HelpScreen), what="help closed")
        await pilot.press("question_mark")
        await wait_until(pilot, lambda: isinstance(app.screen, HelpScreen), what="help again")


async def test_remapped_key_runs_the_action():
    b = mars_mid_execution()
    backend = EngineBackend(b)
    app = make_app(backend=backend, config=ConsoleConfig(keymap={"mission.sync": "S"}))
    backend.app = app
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, b, telemetry=mars_telemetry())
        app.mission_screen.schedule.select("lru1-4")
        await pilot.pause()
        await pilot.press("s")  # no longer bound
        await pilot.pause()
        assert b.mission.find("lru1-4")[2].status == Status.IDLE
        await pilot.press("S")
        await wait_until(
            pilot,
            lambda: b.mission.find("lru1-4")[2].status == Status.IDLE_SYNCHRONIZED,
            what="sync with S",
        )


async def test_command_palette_has_every_action_and_says_what_does_not_apply():
    from console.commands import MissionCommands
    from console.state.actions import ACTIONS

    app = make_app()
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        app.mission_screen.schedule.select("lru1-2")
        await pilot.pause()
        provider = MissionCommands(app.screen)
        hits = [h async for h in provider.discover()]
        # the schedule's actions and the screen switches; the other screens' own actions
        # are offered there
        assert {str(h.display) for h in hits} == {
            a.palette_title
            for a in ACTIONS
            if a.scope in ("mission", "app") and not a.fixed and a.name != "command_palette"
        }
        assert {"Screen: Help", "Screen: Quit"} <= {str(h.display) for h in hits}
        assert "Screen: Fleet" in {str(h.display) for h in hits}
        found = {h.text: h for h in [h async for h in provider.search("delete")]}
        assert "does not apply now: lru1-2 is running on lru1" in found["Mission: Delete"].help
        assert max(found.values(), key=lambda h: h.score).text == "Mission: Delete"
        await pilot.press("ctrl+p")
        await pilot.pause()
        await pilot.press(*"unsync")
        await wait_until(pilot, lambda: "Mission: Unsync" in screen_text(app), what="palette entry")
        await pilot.press("escape", "f3")
        await pilot.pause()
        on_map = {str(h.display) for h in [h async for h in MissionCommands(app.screen).discover()]}
        assert {f"Map: {a.label}" for a in ACTIONS if a.scope == "map"} <= on_map


async def test_unreachable_server_is_one_clear_screen_with_retry_and_quit():
    endpoint = loopback_endpoint(free_port())  # nobody listens there
    app = make_app(connect=endpoint)
    async with app.run_test(size=(100, 24)) as pilot:
        await wait_until(
            pilot,
            lambda: f"Cannot reach the mission server at {endpoint}" in screen_text(app),
            timeout=20,
            what="unreachable screen",
        )
        text = screen_text(app)
        assert isinstance(app.screen, UnreachableScreen)
        assert "r: retry" in text and "Traceback" not in text
        first = app.screen
        await pilot.press("r")
        await wait_until(
            pilot,
            lambda: app.screen is not first and isinstance(app.screen, UnreachableScreen),
            timeout=20,
            what="unreachable again",
        )
        assert app.screen.active_bindings["q"].binding.action == "quit_app"
        app.screen.action_quit_app()  # what q does (pressing it ends the app under the pilot)
        await wait_exit(app)
    assert app.return_code == 3


async def test_reconnecting_disables_changes_and_says_so():
    app = make_app(backend=EngineBackend(Builder()))
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        app.post_message(link_state("reconnecting"))
        await pilot.pause()
        text = screen_text(app)
        assert "⟳ reconnecting" in text
        await pilot.press("a")
        assert "not connected to the mission server (reconnecting)" in status_line(app)
        app.post_message(link_state("connected"))
        await pilot.pause()
        assert "reconnected" in status_line(app)


async def test_robot_going_offline_shows_in_its_header_and_to_its_barrier_partner():
    from console_state import T0

    from backend.protocol.messages import RobotInfo

    app = make_app()
    async with app.run_test(size=(200, 40)) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        assert "b1: waiting for lru1" in screen_text(app)  # lru2 waits for lru1 at b1
        app.post_message(
            fleet_changed(RobotInfo(name="lru1", online=False, since=T0.replace(minute=50)))
        )
        await pilot.pause()
        text = screen_text(app)
        assert "✕ offline since 10:50:07" in text  # lru1 header
        assert "b1: lru1 OFFLINE 10:50:07" in text  # in lru2's column, under its waiting skill


async def test_80x24_is_usable_schedule_then_editor():
    app = make_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        screen = app.mission_screen
        assert screen.has_class("-narrow")
        text = screen_text(app)
        assert "lru1" in text and "lru2" in text and "drive to POI-A" in text
        await pilot.press("right", "right")  # ardea: scrolls horizontally
        await pilot.pause()
        assert "ardea" in screen_text(app)
        await pilot.press("left", "left", "enter")
        await pilot.pause()
        assert screen.has_class("-editing")
        assert " on lru1" in screen_text(app) and "label" in screen_text(app)
        await pilot.press("escape")
        await pilot.pause()
        assert not screen.has_class("-editing")
        assert "drive to POI-A" in screen_text(app)


async def test_save_then_load_a_mission_file_and_undo(tmp_path):
    from backend.files.missions import load_mission
    from console.screens.dialogs import ChoiceScreen, ConfirmScreen, PathPrompt

    b = Builder(TUTORIAL)
    app, backend = engine_app(b)
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, b, online={"lru1": True, "lru2": True})
        # undo / redo of one's own edit
        app.mission_screen.schedule.select("lru2-2")
        await pilot.pause()
        await pilot.press("d")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="confirm")
        await pilot.press("y")
        await wait_until(pilot, lambda: b.mission.find("lru2-2") is None, what="deleted")
        await pilot.press("ctrl+z")
        await wait_until(pilot, lambda: b.mission.find("lru2-2") is not None, what="undone")
        await wait_until(pilot, lambda: "undone" in status_line(app), what="said")
        # save: the library is written beside the file when the reference does not resolve
        target = tmp_path / "saved.yaml"
        await pilot.press("ctrl+s")
        await wait_until(pilot, lambda: isinstance(app.screen, PathPrompt), what="path prompt")
        app.screen.query_one("Input").value = str(target)
        await pilot.press("enter")
        await wait_until(pilot, lambda: isinstance(app.screen, ChoiceScreen), what="save as")
        assert "its state: the statuses and the log as they are" in screen_text(app)
        await pilot.press("enter")  # its state (a plan: every skill idle)
        await wait_until(pilot, lambda: target.exists(), what="file saved")
        await wait_until(pilot, lambda: "saved" in status_line(app), what="said")
        mission, _ = load_mission(target)  # a valid mission file
        assert [s.id for s in mission.tasks["lru2"]] == ["lru2-1", "lru2-2"]
        # load it back (replaces the plan, after a confirmation)
        text = target.read_text().replace("drive next to POI-A", "drive beside POI-A")
        target.write_text(text)
        await pilot.press("ctrl+o")
        await wait_until(pilot, lambda: isinstance(app.screen, PathPrompt), what="path prompt")
        app.screen.query_one("Input").value = str(target)
        await pilot.press("enter")
        await wait_until(
            pilot, lambda: isinstance(app.screen, ChoiceScreen), what="confirm replace"
        )
        assert "Replace, as a plan: unfinished skills idle" in screen_text(app)
        await pilot.press("down", "enter")  # it starts on Cancel
        await wait_until(
            pilot,
            lambda: b.mission.find("lru2-1")[2].label == "drive beside POI-A",
            what="loaded on the server",
        )
        await wait_until(pilot, lambda: "drive beside POI-A" in screen_text(app), what="shown")


async def test_policies_are_typed_inputs_validated_then_applied():
    from backend.core.model import Policies

    b = Builder(TUTORIAL)
    app, backend = engine_app(b)
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, b, online={"lru1": True, "lru2": True})
        screen = app.mission_screen
        screen.schedule.select("lru2-1")
        await wait_until(pilot, lambda: shows(screen.editor, "lru2-1"), what="lru2-1 shown")
        text = screen_text(app)
        assert "policies — applied by the robot itself" in text
        assert "retries" in text and "pause out of comms" in text and "recharge below" in text
        ed = screen.editor
        ed.query_one("#pf-retries").value = "25"
        ed.query_one("#pf-recharge_below").value = "1.5"
        await pilot.pause()
        assert "25: should be less than or equal to 20" in screen_text(app)
        assert (
            str(ed.query_one("#perr-recharge_below").render())
            == "1.5: should be less than or equal to 1"
        )
        ed.action_apply()
        await pilot.pause()
        assert backend.ops == []  # nothing sent while invalid
        ed.query_one("#pf-retries").value = "3"
        ed.query_one("#pf-recharge_below").value = "0.2"
        ed.query_one("#pf-pause_out_of_comms").value = True
        await pilot.pause()
        assert "should be" not in screen_text(app)
        assert "unapplied changes: policies" in screen_text(app)
        ed.action_apply()
        await wait_until(
            pilot,
            lambda: (
                b.mission.find("lru2-1")[2].policies
                == Policies(retries=3, pause_out_of_comms=True, recharge_below=0.2)
            ),
            what="policies applied",
        )
        await wait_until(pilot, lambda: "applied policies" in status_line(app), what="status line")
        await wait_until(
            pilot,
            lambda: (
                ed.loaded_rev == b.mission.find("lru2-1")[2].rev and not ed.loading and not ed.dirty
            ),
            what="reloaded",
        )
        assert ed.query_one("#pf-retries").value == "3"
        # an empty recharge level means off
        ed.query_one("#pf-recharge_below").value = ""
        await wait_until(pilot, lambda: ed.dirty == ["policies"], what="the change seen")
        ed.action_apply()
        await wait_until(
            pilot,
            lambda: b.mission.find("lru2-1")[2].policies.recharge_below is None,
            what="recharge off",
        )
        # read-only like the parameters once the skill is on the robot
        b.sync("lru2", "lru2-1")
        from console_state import state_loaded

        app.post_message(state_loaded(b.snapshot(), b.library, {}))
        await wait_until(pilot, lambda: ed.query("#readonly"), what="read-only")
        assert all(
            w.disabled for w in ed.query("#pf-retries, #pf-pause_out_of_comms, #pf-recharge_below")
        )


async def test_unapplied_edits_are_kept_per_skill_when_the_cursor_moves():
    b = Builder(TUTORIAL)
    app, backend = engine_app(b)
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, b, online={"lru1": True, "lru2": True})
        screen = app.mission_screen
        screen.schedule.select("lru2-1")
        await pilot.pause()
        await pilot.press("enter")  # into the editor
        await pilot.pause()
        screen.editor.query_one("#f-label").value = "drive carefully"
        screen.editor.query_one("#f-speed").value = "0.3"
        await pilot.pause()
        assert "unapplied changes: label, speed" in screen_text(app)
        await pilot.press("escape", "down")  # back to the schedule, next skill
        await pilot.pause()
        assert screen.editor.skill_id == "lru2-2"
        assert "*drive next to POI-A" in screen_text(app)  # the row says it has a draft
        assert screen.editor.query_one("#f-label").value == "find a stone"
        await pilot.press("up")
        await pilot.pause()
        assert screen.editor.query_one("#f-label").value == "drive carefully"
        assert screen.editor.query_one("#f-speed").value == "0.3"
        assert "unapplied changes: label, speed" in screen_text(app)
        await pilot.press("enter", "enter")  # open, apply
        await wait_until(
            pilot, lambda: b.mission.find("lru2-1")[2].label == "drive carefully", what="applied"
        )
        assert b.mission.find("lru2-1")[2].params["speed"] == 0.3
        await wait_until(
            pilot,
            lambda: "*drive" not in screen_text(app) and not screen.editor.dirty,
            what="draft gone",
        )


async def test_a_draft_is_discarded_and_said_when_its_skill_leaves_idle():
    b = Builder(TUTORIAL)
    app, backend = engine_app(b)
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, b, online={"lru1": True, "lru2": True})
        screen = app.mission_screen
        screen.schedule.select("lru2-1")
        await pilot.pause()
        screen.editor.query_one("#f-label").value = "not yet"
        await pilot.pause()
        screen.schedule.select("lru2-2")
        await pilot.pause()
        assert "*drive next to POI-A" in screen_text(app)
        await pilot.press("s")  # sync through lru2-2: lru2-1 goes to the robot
        await wait_until(
            pilot, lambda: "discarded" in status_line(app), what="the draft dropped and said"
        )
        assert (
            "lru2-1 is now queued on lru2: your unapplied changes to it (label) are discarded"
            in status_line(app)
        )
        assert "*drive" not in screen_text(app)
        assert screen.editor.drafts == {}
        # back on it: the skill as it is, read-only
        screen.schedule.select("lru2-1")
        await pilot.pause()
        assert screen.editor.query_one("#f-label").value == "drive next to POI-A"


async def test_a_draft_survives_a_lost_connection():
    b = Builder(TUTORIAL)
    app = make_app(backend=EngineBackend(b))
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, b, online={"lru1": True, "lru2": True})
        screen = app.mission_screen
        screen.schedule.select("lru2-1")
        await pilot.pause()
        screen.editor.query_one("#f-label").value = "kept"
        await wait_until(
            pilot, lambda: "unapplied changes: label" in screen_text(app), what="the change seen"
        )
        app.post_message(link_state("reconnecting"))
        await wait_until(
            pilot, lambda: screen.editor.query("#readonly"), what="read-only while reconnecting"
        )
        assert screen.editor.query_one("#f-label").value == "drive next to POI-A"
        app.post_message(link_state("connected"))
        await wait_until(pilot, lambda: not screen.editor.query("#readonly"), what="editable again")
        await wait_until(
            pilot, lambda: "unapplied changes: label" in screen_text(app), what="the draft said"
        )
        assert screen.editor.query_one("#f-label").value == "kept"


async def test_status_changes_and_telemetry_repaint_the_lines_that_changed():
    from console_state import T0, applied_batch, telemetry_changed

    from backend.core.model import Pose
    from backend.core.ops import Report
    from backend.protocol.messages import Telemetry

    b = mars_mid_execution()
    app = make_app()
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, b, telemetry=mars_telemetry())
        assert "45%" in screen_text(app)
        app.post_message(
            telemetry_changed(
                Telemetry(
                    robot="lru1",
                    pose=Pose(x=21.0, y=8.0),
                    battery=0.5,
                    link=0.9,
                    mode="executing",
                    skill="lru1-2",
                    progress=0.7,
                    eta_s=60,
                    at=T0,
                )
            )
        )
        await pilot.pause()
        text = screen_text(app)
        assert "70%" in text and "ETA 1m00s" in text and "bat 50%" in text and "45%" not in text
        seq = 100
        for sid, status in (
            ("lru1-2", "success"),
            ("lru1-3", "synchwaiting"),
            ("lru1-3", "running"),
        ):
            seq += 1
            applied = b.engine.submit(Report(robot="lru1", seq=seq, id=sid, status=status))
            app.post_message(applied_batch(applied.batch()))
            await pilot.pause()
        text = screen_text(app)
        lru1 = [line.split("│")[0] for line in text.splitlines()]
        assert any("✓ drive to POI-A" in line for line in lru1)
        assert any("▶ identif" in line and "LRU2" in line for line in lru1)  # the barrier skill
        assert "▶ lru1-3 running" in text  # header activity
        assert not any("▶ explore east plain" in line for line in lru1)
        assert screen_text(app) == text  # stable: nothing left half-painted


async def test_a_long_label_is_cut_but_never_the_attempt_number():
    from backend.core.ops import EditSkill

    b = Builder()
    b.engine.submit(EditSkill(id="ardea-1", label="take off from the lander pad"))
    b.sync("ardea", "ardea-1")
    b.report("ardea", "ardea-1", "running")
    b.report("ardea", "ardea-1", "failure", "rotor check failed")
    new = b.engine.plan_retry(Retry(id="ardea-1"))
    b.engine.submit(RetryAck(robot="ardea", failed_id="ardea-1", skill=new))
    b.engine.release("ardea")
    app = make_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, b)
        text = screen_text(app)
        # cut in the middle (both ends of the label stay), never the attempt number
        assert "✗ take off…nder pad│" in text
        assert "● take of…er pad #2│" in text


async def test_quitting_with_unapplied_changes_asks_first():
    from console.screens.dialogs import QuitScreen

    b = Builder(TUTORIAL)
    app = make_app(backend=EngineBackend(b))
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, b, online={"lru1": True, "lru2": True})
        app.mission_screen.schedule.select("lru2-1")
        await pilot.pause()
        app.mission_screen.editor.query_one("#f-label").value = "unsaved"
        await pilot.pause()
        await pilot.press("ctrl+q")
        await wait_until(pilot, lambda: isinstance(app.screen, QuitScreen), what="the question")
        assert "unapplied changes in the editor to lru2-1" in screen_text(app)
        await pilot.press("n")
        await wait_until(pilot, lambda: not isinstance(app.screen, QuitScreen), what="back")
        assert app.return_code is None
        await pilot.press("ctrl+q")
        await wait_until(
            pilot, lambda: isinstance(app.screen, QuitScreen), what="the question again"
        )
        await pilot.press("q")
        await wait_exit(app)
        assert app.return_code == 0


async def test_at_80x24_a_draft_survives_leaving_the_editor_and_editing_another_skill():
    b = Builder(TUTORIAL)
    app, backend = engine_app(b)
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, b, online={"lru1": True, "lru2": True})
        screen = app.mission_screen
        screen.schedule.select("lru2-1")
        await pilot.pause()
        await pilot.press("enter", *"careful ")  # the label field has the focus
        await pilot.pause()
        assert "unapplied changes: label" in screen_text(app)
        await pilot.press("escape", "down")
        await pilot.pause()
        assert "*drive next to POI-A" in screen_text(app)
        await pilot.press("enter")  # edit lru2-2: lru2-1's changes become its draft
        await wait_until(
            pilot,
            lambda: screen.editor.skill_id == "lru2-2" and not screen.editor.loading,
            what="lru2-2 in the editor",
        )
        assert screen.editor.drafts.keys() == {"lru2-1"}
        await pilot.press("escape", "up", "enter")
        await wait_until(
            pilot,
            lambda: screen.editor.skill_id == "lru2-1" and not screen.editor.loading,
            what="lru2-1 again",
        )
        assert screen.editor.query_one("#f-label").value.startswith("careful ")
        await pilot.press("enter")  # enter in a field applies
        await wait_until(
            pilot, lambda: b.mission.find("lru2-1")[2].label.startswith("careful "), what="applied"
        )


async def test_a_partner_reaching_the_barrier_updates_the_waiting_robots_column():
    from console_state import applied_batch

    from backend.core.ops import Report

    b = mars_mid_execution()
    app = make_app()
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, b, telemetry=mars_telemetry())
        assert "b1: waiting for lru1" in screen_text(app)
        for seq, (sid, status) in enumerate(
            (("lru1-2", "success"), ("lru1-3", "synchwaiting")), start=100
        ):
            app.post_message(
                applied_batch(
                    b.engine.submit(Report(robot="lru1", seq=seq, id=sid, status=status)).batch()
                )
            )
            await pilot.pause()
        text = screen_text(app)
        assert "b1: waiting for lru1" not in text
        assert text.count("b1: all partners ready") == 2  # in both columns
