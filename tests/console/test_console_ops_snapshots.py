"""The screens issue 27 changed, at 80x24 and 120x40, with a sim at speed 10:
every time in sim time (the top bar's clock, ages, the 10m link delay, the
timeline), the keys from the actions table, the cancel confirmation, the
picker that got the keys typed after `a`, the map's line on what is under its
cursor. Deterministic: state, map and sim status injected as messages, the
wall clock pinned three seconds after the command was queued, TZ=UTC, no
animations or cursor blink. Each asserts real content first; every SVG was
looked at (rendered to PNG) when written.
Update with: pytest tests/console/test_console_ops_snapshots.py --snapshot-update
"""

from __future__ import annotations

from datetime import timedelta

import pytest
from console_state import T0, fleet_changed, inject, mars_telemetry, screen_text, wait_until
from map_state import map_message, mars_snapshot
from plan_state import ONLINE, plan_app, risky_mars, sim_status
from textual import events

from backend.core.ops import Sync
from backend.protocol.messages import RobotInfo

SIZES = {"80x24": (80, 24), "120x40": (120, 40)}


async def _at_speed_10(app, pilot) -> None:
    """Mars mid-way, lru2 asked to sync lru2-5 and lru2-6 at T0 (pending), a sim at
    speed 10 with a 10m link delay; the wall clock 3 s later (30 sim seconds)."""
    b = app.backend.b
    b.engine.clock = lambda: T0
    b.engine.submit(Sync(robot="lru2", through="lru2-6"))
    app.clock = lambda: T0 + timedelta(seconds=3)
    app.model.plan.status = sim_status(delay=600.0).model_copy(update={"speed": 10.0})
    await inject(app, pilot, b, online=ONLINE, telemetry=mars_telemetry())
    snap = mars_snapshot()
    app.post_message(map_message(snap.model_copy(update={"sim_time": 1608.0, "speed": 10.0})))
    app.post_message(
        fleet_changed(RobotInfo(name="lru2", online=True, since=T0, heard=T0, delay_s=60.0))
    )
    app.ops.refused("Run refused: [lru1] lru1 is already executing lru1-2 (running)", "lru1", None)
    await wait_until(pilot, lambda: app.model.clock.simulated, what="the sim's clock")
    app.refresh_plan(force=True)
    app.mission_screen.schedule.select("lru2-5")
    await pilot.pause()
    app.mission_screen.freshness_tick()
    await pilot.pause()


def _keys(*keys: str):
    async def go(app, pilot):
        for k in keys:
            await pilot.press(k)
            await pilot.pause()

    return go


async def _picker(app, pilot):
    app.mission_screen.schedule.select("lru1-4")
    await pilot.pause()
    for k in "ascience":  # one burst: the picker gets the word
        app.post_message(events.Key(k, k))
    await wait_until(pilot, lambda: not app.typeahead.holding, what="keys released")


SCREENS = {
    "schedule": (_keys(), ("sim 0:26:48", "sync #1 queued 30s ago", "w Cancel cmd")),
    "timeline": (_keys("f7"), ("plan ends sim", "link delay 10m00s")),
    "checks": (_keys("f8"), ("waive",)),
    "map": (_keys("f3"), ("here: ", "cursor (")),
    "fleet": (_keys("f4"), ("4 online", "cancel a command")),
    "log": (_keys("f5"), ("sim 0:26:48", "refusal")),
    "alerts": (_keys("f6"), ("sim 0:26:48", "acknowledge")),
    "help": (_keys("f1"), ("operator console", "Navigation")),
    "cancel": (_keys("w"), ("Cancel sync #1 to lru2 (lru2-5, lru2-6)?", "Keep it (n)")),
    "picker": (_picker, ("take_science_image", "science")),
}


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("screen", SCREENS)
def test_screens_at_speed_10(snap_compare, screen, size):
    go, expect = SCREENS[screen]

    async def run_before(pilot):
        app = pilot.app
        await _at_speed_10(app, pilot)
        await go(app, pilot)
        await pilot.pause()
        app.clear_notifications()
        await pilot.pause()
        text = screen_text(app)
        for needle in expect:
            assert needle in text, f"{needle!r} not on the {screen} screen:\n{text}"
        assert "10:42" not in text  # no wall time anywhere: T0 is 10:42:07

    app, _ = plan_app(risky_mars())
    assert snap_compare(app, terminal_size=SIZES[size], run_before=run_before)
