"""Snapshots of the console at fixed sizes (pytest-textual-snapshot).

State is injected as messages (no network, no clocks, TZ=UTC, no animations,
no cursor blink), so the SVGs are deterministic. Every snapshot here was
looked at when it was (re)written; each test also asserts on real content
first, so a blank screen of an app that failed to start cannot pass.
Update with: pytest tests/console/test_console_snapshots.py --snapshot-update
"""

from __future__ import annotations

from console_state import (
    DATA,
    MARS,
    T0,
    Builder,
    inject,
    make_app,
    mars_mid_execution,
    mars_telemetry,
    screen_text,
)

from backend.core.model import Pose
from backend.core.ops import DeleteSkills
from backend.protocol.messages import Telemetry
from console.screens.dialogs import UnreachableScreen

WIDE = (150, 40)


def _prepare(builder, *, select=None, online=None, telemetry=None, after=None, expect=()):
    async def run_before(pilot):
        app = pilot.app
        await inject(app, pilot, builder, online=online, telemetry=telemetry)
        if select:
            app.mission_screen.schedule.select(select)
            await pilot.pause()
        if after is not None:
            await after(pilot)
        await pilot.pause()
        await app.workers.wait_for_complete()
        await pilot.pause()
        text = screen_text(app)
        for needle in expect:  # real content, not a blank screen
            assert needle in text, f"{needle!r} not on screen:\n{text}"

    return run_before


def test_empty_mission(snap_compare):
    b = Builder(MARS)
    b.engine.submit(DeleteSkills(ids=sorted(b.mission.all_ids())))
    assert snap_compare(
        make_app(),
        terminal_size=(110, 24),
        run_before=_prepare(b, expect=("lru1", "ardea", "nothing on robot", "empty plan")),
    )


def test_mars_mid_execution_every_status_and_a_barrier(snap_compare):
    assert snap_compare(
        make_app(),
        terminal_size=WIDE,
        run_before=_prepare(
            mars_mid_execution(),
            telemetry=mars_telemetry(),
            expect=("[b1]", "45%", "✗", "‖", "◷", "offline 10:42:07"),
        ),
    )


def test_editor_every_parameter_type(snap_compare):
    # bool, int, float, str, list, dict, pose, position, area, enum, marker, robot
    b = Builder(DATA / "every_type.yaml")
    assert snap_compare(
        make_app(),
        terminal_size=(130, 80),
        run_before=_prepare(
            b,
            online={"rover1": True, "rover2": True},
            select="rover1-1",
            expect=(
                "enabled",
                "samples",
                "speed",
                "note",
                "sensors",
                "camera",
                "goal",
                "target",
                "region",
                "filter",
                "landmark",
                "partner",
                "layered, reddish",
            ),
        ),
    )


def test_editor_explore_area_bound_to_a_marker(snap_compare):
    # area (bound to ROI-east), float with unit and bounds, bool, list
    assert snap_compare(
        make_app(),
        terminal_size=WIDE,
        run_before=_prepare(
            Builder(MARS),
            select="lru1-2",
            expect=("@ROI-east", "max_duration", "return_to_start", "sensors"),
        ),
    )


def test_editor_pick_stone_marker_and_position(snap_compare):
    assert snap_compare(
        make_app(),
        terminal_size=WIDE,
        run_before=_prepare(
            Builder(MARS), select="lru2-4", expect=("region", "marker area", "target")
        ),
    )


def test_editor_static_robot_enum_and_int(snap_compare):
    # the lander (a static robot, collapsed at the end) and its load_box: enum, int with bounds
    assert snap_compare(
        make_app(),
        terminal_size=WIDE,
        run_before=_prepare(Builder(MARS), select="lander-1", expect=("slot", "int 1..4", "box")),
    )


def test_validation_error_next_to_the_field(snap_compare):
    async def after(pilot):
        editor = pilot.app.mission_screen.editor
        editor.query_one("#f-speed").value = "7.5"
        editor.query_one("#f-tolerance").value = "abc"
        await pilot.pause()

    assert snap_compare(
        make_app(),
        terminal_size=WIDE,
        run_before=_prepare(
            Builder(MARS),
            select="lru2-5",
            after=after,
            expect=("7.5 m/s is above the maximum 1 m/s", "expected a number, got 'abc'"),
        ),
    )


def test_editor_policies_with_errors_and_a_draft_on_another_skill(snap_compare):
    async def after(pilot):
        screen = pilot.app.mission_screen
        screen.editor.query_one("#f-label").value = "drive, then wait"  # a draft on lru2-4...
        await pilot.pause()
        screen.schedule.select("lru2-5")  # ...kept when the cursor moves on
        await pilot.pause()
        editor = screen.editor
        editor.query_one("#pf-retries").value = "25"
        editor.query_one("#pf-pause_out_of_comms").value = True
        editor.query_one("#pf-recharge_below").value = "0.25"
        await pilot.pause()
        # the policies at the top (the Contingency group follows them)
        editor.scroll_to_widget(editor.query_one("#policy-retries"), animate=False, top=True)
        await pilot.pause()

    assert snap_compare(
        make_app(),
        terminal_size=WIDE,
        run_before=_prepare(
            Builder(MARS),
            select="lru2-4",
            after=after,
            expect=(
                "*pick the stone",
                "*back to lander",
                "25: should be less than or equal to 20",
                "recharge below",
            ),
        ),
    )


def test_read_only_running_skill_with_reason(snap_compare):
    assert snap_compare(
        make_app(),
        terminal_size=WIDE,
        run_before=_prepare(
            mars_mid_execution(),
            telemetry=mars_telemetry(),
            select="lru1-2",
            expect=("read-only: lru1-2 is running on lru1",),
        ),
    )


def test_help_screen(snap_compare):
    async def after(pilot):
        await pilot.press("f1")
        await pilot.pause()

    assert snap_compare(
        make_app(),
        terminal_size=(110, 50),
        run_before=_prepare(
            mars_mid_execution(), after=after, expect=("Navigation", "Synchronization", "Execution")
        ),
    )


def test_80x24_mid_execution(snap_compare):
    assert snap_compare(
        make_app(),
        terminal_size=(80, 24),
        run_before=_prepare(
            mars_mid_execution(), telemetry=mars_telemetry(), expect=("lru1", "lru2", "[b1]")
        ),
    )


def test_80x24_editor(snap_compare):
    async def after(pilot):
        await pilot.press("enter")
        await pilot.pause()

    assert snap_compare(
        make_app(),
        terminal_size=(80, 24),
        run_before=_prepare(
            mars_mid_execution(),
            telemetry=mars_telemetry(),
            select="lru1-4",
            after=after,
            expect=("lru1-4  take_science_image on", "filter", "+2 robots →"),
        ),
    )


def test_unreachable_server(snap_compare):
    async def run_before(pilot):
        pilot.app.push_screen(
            UnreachableScreen(
                "tcp/127.0.0.1:7447",
                "the router at tcp/127.0.0.1:7447 cannot be reached "
                "(nothing listens there, or the connection was refused)",
            )
        )
        await pilot.pause()
        assert "Cannot reach the mission server" in screen_text(pilot.app)

    assert snap_compare(make_app(), terminal_size=(90, 20), run_before=run_before)


def _map_prepare(expect, *, zoom_in=False):
    from map_state import map_message

    b = mars_mid_execution()

    async def run_before(pilot):
        app = pilot.app
        await inject(app, pilot, b, telemetry=mars_telemetry())
        app.post_message(map_message())
        app.mission_screen.schedule.select("lru2-5")  # its typed goal is labelled on the map
        await pilot.pause()
        await pilot.press("f3")
        await pilot.pause()
        if zoom_in:
            await pilot.press("plus")
        await pilot.pause()
        text = screen_text(app)
        for needle in expect:
            assert needle in text, f"{needle!r} not on screen:\n{text}"

    return run_before


def test_map_robots_markers_explored_area(snap_compare):
    assert snap_compare(
        make_app(),
        terminal_size=(120, 40),
        run_before=_map_prepare(
            ("lru1 ▶", "lru2 ◷", "POI-B", "ROI-north", "Legend", "sampling region"), zoom_in=True
        ),
    )


def test_map_in_16_colours(snap_compare):
    """Over SSH with TERM=xterm: explored area, coverage, markers and robots
    still apart (each status has its own ANSI colour, glyphs carry meaning)."""
    app = make_app(colors=16)
    assert snap_compare(
        app,
        terminal_size=(120, 40),
        run_before=_map_prepare(("lru1 ▶", "lru2 ◷", "POI-B", "Legend"), zoom_in=True),
    )


def test_map_80x24(snap_compare):
    assert snap_compare(
        make_app(),
        terminal_size=(80, 24),
        run_before=_map_prepare(("lru1", "ROI-north", "cursor (")),
    )


def test_map_parameter_chooser(snap_compare):
    # b with a pose marker on a skill with two pose parameters: the list asks which one
    from map_state import map_message

    async def run_before(pilot):
        app = pilot.app
        await inject(
            app,
            pilot,
            Builder(DATA / "transport.yaml"),
            online={"lru1": True},
            telemetry=[
                Telemetry(
                    robot="lru1", pose=Pose(x=10.0, y=5.0, yaw=0.5), battery=0.8, link=0.9, at=T0
                )
            ],
        )
        app.post_message(map_message())
        app.mission_screen.schedule.select("lru1-2")
        await pilot.pause()
        await pilot.press("f3")
        await pilot.pause()
        app.screen.select_marker("POI-A")
        await pilot.pause()

        def shows(*needles):  # screen_text: the top screen only
            text = screen_text(app)
            for needle in needles:
                assert needle in text, f"{needle!r} not on screen:\n{text}"

        shows("lru1", "POI-A", "DEPOT", "Legend")  # the map...
        await pilot.press("b")
        await pilot.pause()
        await pilot.pause()
        shows(
            "Bind POI-A to which parameter of lru1-2?", "@POI-B", "(2,0)", "enter: choose"
        )  # ...and the dialog over it

    assert snap_compare(make_app(), terminal_size=(120, 40), run_before=run_before)


def test_observer_account_read_only(snap_compare):
    # logged in as an observer: the top bar says so, the editor and every change action
    # give the reason
    async def after(pilot):
        from console_state import account_known

        pilot.app.post_message(account_known("read-only: logged in as observer watch"))
        await pilot.pause()
        await pilot.press("d")
        await pilot.pause()

    assert snap_compare(
        make_app(),
        terminal_size=WIDE,
        run_before=_prepare(
            Builder(MARS),
            select="lru1-2",
            after=after,
            expect=(
                "read-only: logged in as observer watch",
                "Delete: read-only: logged in as observer watch",
            ),
        ),
    )
