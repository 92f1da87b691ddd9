"""Snapshots of the timeline (F7) and the plan checks (F8) at 80x24, the
timeline in 16 colours, and the schedule's check glyphs (deterministic: state
and map injected as messages, the clock pinned, TZ=UTC, no animations or
cursor blink). Each asserts real content first. Every SVG was looked at
(rendered to PNG) when written.
Update with: pytest tests/console/test_console_plan_snapshots.py --snapshot-update
"""

from __future__ import annotations

from console_state import mars_telemetry, screen_text
from plan_state import plan_app, risky_mars, show_plan


def _scenario(*keys: str, expect=()):
    async def run_before(pilot):
        app = pilot.app
        b = app.backend.b
        await show_plan(app, pilot, b, telemetry=mars_telemetry())
        app.model.selection.skill = "lru1-3"
        for k in keys:
            await pilot.press(k)
            await pilot.pause()
        await app.workers.wait_for_complete()
        await pilot.pause()
        text = screen_text(app)
        for needle in expect:
            assert needle in text, f"{needle!r} not on screen:\n{text}"

    return run_before


def _app(**kw):
    app, _ = plan_app(risky_mars())
    if kw.get("colors") == 16:
        app._use_16_colours()
    return app


TIMELINE = ("lru2", "ardea", "plan ends", "link delay 1m30s", "lru1-3 identify stone", "▼", "┆")


def test_timeline_80x24(snap_compare):
    assert snap_compare(_app(), terminal_size=(80, 24), run_before=_scenario("f7", expect=TIMELINE))


def test_timeline_in_16_colours(snap_compare):
    assert snap_compare(
        _app(colors=16), terminal_size=(80, 24), run_before=_scenario("f7", expect=TIMELINE)
    )


def test_plan_checks_80x24(snap_compare):
    assert snap_compare(
        _app(),
        terminal_size=(80, 24),
        run_before=_scenario(
            "f8", expect=("energy.empty:ardea-8", "coverage.stranded:lru2-9", "not waived")
        ),
    )


def test_schedule_with_check_glyphs_80x24(snap_compare):
    assert snap_compare(
        _app(), terminal_size=(80, 24), run_before=_scenario(expect=("survey the north", "✖", "⚠"))
    )
