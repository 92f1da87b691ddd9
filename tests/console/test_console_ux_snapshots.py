"""Snapshots of what issue 22 changed, at 80x24 and 120x40: a stale robot,
the editor as a side panel (degrees), edit and retry, search, the save
prompt started from the shipped folder, the quit question. Deterministic:
state injected as messages, the clock pinned, no animations or blink; each
asserts real content first. Every SVG was looked at when written.
Update with: pytest tests/console/test_console_ux_snapshots.py --snapshot-update
"""

from __future__ import annotations

from datetime import timedelta

from console_state import (
    MARS,
    T0,
    Builder,
    alert_received,
    applied_batch,
    engine_app,
    fleet_changed,
    inject,
    make_app,
    mars_mid_execution,
    mars_telemetry,
    screen_text,
    settle,
    telemetry_changed,
    wait_until,
)

from backend.core.ops import EditSkill
from backend.protocol.messages import Alert, RobotInfo, Telemetry
from console.state.files import SHIPPED_MISSIONS

ONLINE = {"lru1": True, "lru2": True, "ardea": True, "lander": True}


def _shows(app, *needles):
    text = screen_text(app)
    for needle in needles:
        assert needle in text, f"{needle!r} not on screen:\n{text}"


def _settled(run, *, workers: bool = True):
    """`run`, then the app settled (`workers` False: a dialog's worker waits for it)."""

    async def run_before(pilot):
        await run(pilot)
        if workers:
            await pilot.app.workers.wait_for_complete()
        await pilot.pause()
        pilot.app.clear_notifications()
        await pilot.pause()

    return run_before


def test_stale_robot_80x24(snap_compare):
    """The sim killed: lru1 offline 25 s, lru2 silent; the others live."""

    async def run(pilot):
        app = pilot.app
        now = [T0]
        app.clock = lambda: now[0]
        await inject(app, pilot, mars_mid_execution(), online=ONLINE, telemetry=mars_telemetry())
        now[0] = T0 + timedelta(seconds=25)
        app.post_message(fleet_changed(RobotInfo(name="lru1", online=False, since=T0)))
        gone = Alert(id=1, kind="offline", robot="lru1", message="robot lru1 went offline", at=T0)
        app.post_message(alert_received(gone))  # the server's
        for r in ("ardea", "lander"):  # still heard
            app.post_message(telemetry_changed(Telemetry(robot=r, battery=0.9, link=0.8, at=T0)))
        await pilot.pause()
        app.mission_screen.freshness_tick()
        await pilot.pause()
        # lru1 probably drives on (the now-cast); lru2 waits where it was seen waiting
        _shows(app, "25s ago ≈ lru1-2 ", "45% as of 25s ago", "25s ago: ◷ lru2-3")

    assert snap_compare(make_app(), terminal_size=(80, 24), run_before=_settled(run))


def test_side_editor_in_degrees_120x40(snap_compare):
    async def run(pilot):
        app = pilot.app
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        app.mission_screen.schedule.select("lru2-5")
        ed = app.mission_screen.editor
        await wait_until(pilot, lambda: ed.skill_id == "lru2-5" and not ed.loading, what="shown")
        _shows(app, "lru2-5  drive_to on lru2", "yaw°", "lander", "⏎ Edit s Sync")

    assert snap_compare(make_app(), terminal_size=(120, 40), run_before=_settled(run))


def test_edit_and_retry_80x24(snap_compare):
    b = Builder(MARS)
    b.sync("lru1", "lru1-2")
    b.report("lru1", "lru1-1", "running")
    b.report("lru1", "lru1-1", "failure", "wheel stuck in sand")
    app, _ = engine_app(b)

    async def run(pilot):
        await inject(pilot.app, pilot, b)
        pilot.app.mission_screen.schedule.select("lru1-1")
        await pilot.pause()
        await pilot.press("T")
        await wait_until(pilot, lambda: pilot.app.mission_screen.editor.skill_id == "lru1-1.2")
        await pilot.pause()
        _shows(pilot.app, "lru1-1.2  drive_to on", "attempt 2", "⏎ Apply", "+2 robots →")

    assert snap_compare(app, terminal_size=(80, 24), run_before=_settled(run))


def test_search_80x24(snap_compare):
    async def run(pilot):
        await inject(pilot.app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        await pilot.press("slash", *"stone")
        await pilot.pause()
        _shows(pilot.app, "Find a skill", "lru2-4  pick the stone (pick_stone)", "4 skills")

    assert snap_compare(make_app(), terminal_size=(80, 24), run_before=_settled(run))


def test_save_prompt_started_from_the_shipped_folder_80x24(snap_compare, monkeypatch):
    # the repository as the home folder, so the paths on screen do not depend on where it is
    monkeypatch.setenv("HOME", str(SHIPPED_MISSIONS.parent))
    monkeypatch.chdir(SHIPPED_MISSIONS)
    b = Builder(MARS)
    app, _ = engine_app(b)

    async def run(pilot):
        await inject(pilot.app, pilot, b)
        await pilot.press("ctrl+s")
        await pilot.pause()
        field = pilot.app.screen.query_one("#path")
        assert field.value == "~/mars_sample_return.yaml"  # not over the example
        field.value = "~/missions/mars_sample_return.yaml"
        await pilot.pause()
        _shows(pilot.app, "mars_sample_return.yaml exists: you will be asked before")

    assert snap_compare(app, terminal_size=(80, 24), run_before=_settled(run, workers=False))


def test_quit_question_with_robots_running_80x24(snap_compare):
    from console.cli import DEMO_QUITS

    async def run(pilot):
        b = mars_mid_execution()
        await inject(pilot.app, pilot, b, telemetry=mars_telemetry())
        sid = b.mission.tasks["lru1"][4].id  # an edit not saved to a file
        pilot.app.post_message(
            applied_batch(b.engine.submit(EditSkill(id=sid, label="edited")).batch())
        )
        await settle(pilot)
        await pilot.press("ctrl+q")
        await pilot.pause()
        _shows(pilot.app, "Quit now?", "lru1 is running (lru1-2)", "Save, then quit (s)")

    app = make_app(quitting_stops=DEMO_QUITS)
    assert snap_compare(app, terminal_size=(80, 24), run_before=_settled(run))
