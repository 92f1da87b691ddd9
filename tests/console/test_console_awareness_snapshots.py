"""Snapshots of the fleet, event-log and alert screens, of the schedule under
every shipped theme, and in 16 colours (deterministic: state injected as
messages, the log's clock pinned, TZ=UTC, no animations or cursor blink).
Each asserts real content first. Every SVG was looked at when written.
Update with: pytest tests/console/test_console_awareness_snapshots.py --snapshot-update
"""

from __future__ import annotations

import pytest
from console_state import (
    awareness_scenario,
    inject,
    make_app,
    mars_mid_execution,
    mars_telemetry,
    screen_text,
)

from console.themes.loader import SHIPPED_DIR, load_themes


def _scenario(*keys: str, expect=()):
    async def run_before(pilot):
        app = pilot.app
        await awareness_scenario(app, pilot)
        app.clear_notifications()  # the toasts would cover the screen under test
        for k in keys:
            await pilot.press(k)
            await pilot.pause()
        await app.workers.wait_for_complete()
        await pilot.pause()
        text = screen_text(app)
        for needle in expect:
            assert needle in text, f"{needle!r} not on screen:\n{text}"

    return run_before


def test_fleet_screen(snap_compare):
    assert snap_compare(
        make_app(),
        terminal_size=(110, 30),
        run_before=_scenario(
            "f4", expect=("4 robots, 2 online", "lru_manipulator", "modules: nav 2.1.0")
        ),
    )


def test_fleet_filtered_by_capability_80x24(snap_compare):
    assert snap_compare(
        make_app(),
        terminal_size=(80, 24),
        run_before=_scenario("f4", *"pick_stone", expect=("1 match 'pick_stone'", "arm 0.9.3")),
    )


def test_event_log(snap_compare):
    assert snap_compare(
        make_app(),
        terminal_size=(130, 30),
        run_before=_scenario(
            "f5", expect=("ada@host-4711-a1b2c3", "✗ lru2-2 failure", "Run refused: [lru1]")
        ),
    )


def test_alert_list(snap_compare):
    assert snap_compare(
        make_app(),
        terminal_size=(120, 24),
        run_before=_scenario(
            "f6", "down", "enter", expect=("4 unacknowledged of 5", "low battery", "server")
        ),
    )


def _schedule(expect=("[b1]", "45%", "✗", "‖", "◷")):
    async def run_before(pilot):
        await inject(pilot.app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        await pilot.pause()
        text = screen_text(pilot.app)
        for needle in expect:
            assert needle in text, f"{needle!r} not on screen:\n{text}"

    return run_before


THEMES = sorted(load_themes([SHIPPED_DIR])[0])


@pytest.mark.parametrize("theme", THEMES)
def test_schedule_mid_execution_under_each_theme(snap_compare, theme):
    assert snap_compare(make_app(theme=theme), terminal_size=(120, 32), run_before=_schedule())


def test_schedule_in_16_colours(snap_compare):
    app = make_app(colors=16)
    assert snap_compare(app, terminal_size=(120, 32), run_before=_schedule())


def test_alert_badge_on_the_schedule_80x24(snap_compare):
    assert snap_compare(
        make_app(), terminal_size=(80, 24), run_before=_scenario(expect=("⚠ 5 alerts (F6)", "lru1"))
    )
