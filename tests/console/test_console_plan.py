"""The plan's timeline (F7) and checks (F8) screens, check glyphs on the
schedule, the local sync gate, and waiving from the console (run_test)."""

from __future__ import annotations

from console_state import mars_mid_execution, mars_telemetry, screen_text, wait_until
from plan_state import crossed, plan_app, show_plan

DEADLOCK = "barrier.deadlock:b2+b3"


async def test_the_timeline_shows_lanes_the_end_and_the_selection():
    builder = mars_mid_execution()
    app, _ = plan_app(builder)
    async with app.run_test(size=(100, 30)) as pilot:
        await show_plan(app, pilot, builder, telemetry=mars_telemetry())
        app.model.selection.skill = "lru1-2"
        await pilot.press("f7")
        await pilot.pause()
        text = screen_text(app)
        for needle in ("timeline", "lru1", "lru2", "ardea", "lander", "plan ends", "critical:"):
            assert needle in text, f"{needle!r} not on screen:\n{text}"
        assert "link delay 1m30s" in text  # the band's length, said too
        assert "lru1-2 explore east plain" in text  # the selection in a line
        assert "battery 82%→" in text  # from telemetry
        await pilot.press("right")
        await pilot.pause()
        assert app.model.selection.skill == "lru1-3"
        assert "waits" in screen_text(app) or "lru1-3" in screen_text(app)
        await pilot.press("down")
        await pilot.pause()
        assert app.model.owner(app.model.selection.skill) == "lru2"
        before = app.screen.win.dt
        await pilot.press("plus")
        assert app.screen.win.dt < before
        await pilot.press("minus", "minus")
        assert app.screen.win.dt > before
        await pilot.press("enter")  # back to the schedule, on the same skill
        await pilot.pause()
        assert app.screen is app.mission_screen
        assert app.mission_screen.schedule.cursor_id == app.model.selection.skill


async def test_clicking_a_bar_selects_its_skill():
    builder = mars_mid_execution()
    app, _ = plan_app(builder)
    async with app.run_test(size=(100, 30)) as pilot:
        await show_plan(app, pilot, builder, telemetry=mars_telemetry())
        await pilot.press("f7")
        await pilot.pause()
        view = app.screen.view
        lane = view.order.index("lru1") * 2
        bar = next(b for b in view.row_bars[lane] if b.id == "lru1-3")
        x = view.name_w + view.win.col(bar.start) + 1
        await pilot.click(view, offset=(x, 2 + lane))
        await pilot.pause()
        assert app.model.selection.skill == "lru1-3"


async def test_checks_glyphs_local_sync_gate_and_waiving_from_the_console():
    builder = crossed()
    app, backend = plan_app(builder)
    async with app.run_test(size=(100, 30)) as pilot:
        await show_plan(app, pilot, builder, site=False)
        # the schedule: ✖ on the barrier skills; sync through one says why not
        text = screen_text(app)
        assert "✖" in text
        app.mission_screen.schedule.select("lru1-1")
        await pilot.pause()
        await pilot.press("s")
        await pilot.pause()
        assert "unwaived plan error barrier.deadlock:b2+b3" in app.mission_screen.message
        assert not any(type(op).__name__ == "Sync" for op in backend.ops)
        # the checks screen lists it; w asks for a reason and waives
        await pilot.press("f8")
        await pilot.pause()
        text = screen_text(app)
        assert DEADLOCK in text and "1 error(s)" in text
        await pilot.press("w")
        await pilot.pause()
        await pilot.press(*"released by hand", "enter")
        await wait_until(pilot, lambda: DEADLOCK in builder.mission.waivers, what="the waiver")
        app.refresh_plan(force=True)
        await pilot.pause()
        text = screen_text(app)
        assert "waived at revision" in text and "released by hand" in text
        assert "0 error(s), 0 warning(s), 1 waived" in text
        # every console's log says who waived what
        log = [e.text for e in app.event_log.entries]
        assert any("waived barrier.deadlock:b2+b3: released by hand" in t for t in log), log
        # the sync now goes (the engine's gate agrees)
        await pilot.press("f2")
        await pilot.pause()
        assert app.mission_screen.why_disabled("sync") is None
        # u withdraws it
        await pilot.press("f8", "u")
        await wait_until(pilot, lambda: not builder.mission.waivers, what="the withdrawal")


async def test_the_schedule_and_availability_without_findings_are_unchanged():
    builder = mars_mid_execution()
    app, _ = plan_app(builder)
    async with app.run_test(size=(100, 30)) as pilot:
        await show_plan(app, pilot, builder, site=False)
        assert app.model.plan.findings == []
        assert "✖" not in screen_text(app) and "⚠" not in screen_text(app)
