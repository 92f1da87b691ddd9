"""The now-cast on the console (issue 34.3): a robot known only by an old report
is drawn where it probably is now (hollow, ≈, dotted from where it was last
known), and each new report logs how far the prediction for its time was.
State injected as messages, the clock pinned."""

from __future__ import annotations

import logging
from datetime import timedelta

from console_state import (
    T0,
    fleet_changed,
    inject,
    make_app,
    mars_mid_execution,
    mars_telemetry,
    screen_text,
    wait_until,
)

from backend.core.model import Pose
from backend.core.plan.forecast import Forecaster
from backend.core.plan.inputs import PlanInputs, RobotNow
from backend.protocol.messages import RobotInfo, Telemetry
from console.state.nowcast import NowcastView, nowcast_words, robot_nowcast


def _rover_mission():
    from tests.core.plan.helpers import LIBRARY, mission, pose, skill

    m = mission(
        {"r1": "rover"},
        {"r1": [skill("r1-1", "drive", "running", goal=pose(100, 0), speed=1.0)]},
    )
    return m, LIBRARY


def test_the_next_report_logs_how_far_the_prediction_was(caplog):
    m, library = _rover_mission()
    first = Telemetry(robot="r1", pose=Pose(x=0, y=0), skill="r1-1", progress=0.0, at=T0)
    now = RobotNow(at=T0.timestamp(), x=0.0, y=0.0, battery=1.0, skill="r1-1", progress=0.0)
    fc = Forecaster(library).forecast(m, PlanInputs(now=T0.timestamp(), robots={"r1": now}))
    view = NowcastView()
    view.reported(fc, m, {"r1": first}, None)  # the basis: nothing to compare yet
    assert view.errors == {}
    later = Telemetry(
        robot="r1", pose=Pose(x=37, y=0), skill="r1-1", progress=0.37, at=T0 + timedelta(seconds=40)
    )
    with caplog.at_level(logging.INFO, logger="console.state.nowcast"):
        view.reported(fc, m, {"r1": later}, None)
    err = view.errors["r1"]
    assert round(err.position_m, 3) == 3.0 and round(err.progress, 3) == 0.03
    assert err.ahead_s == 40.0
    assert "now-cast of r1, 40.0 s ahead: 3.00 m off" in caplog.text
    nc = view.at(fc, m, T0.timestamp() + 50, None)["r1"]
    assert nowcast_words(nc).startswith("≈ now: r1-1 50%, battery ")


async def _lru1_far_and_later(app, pilot, seconds: float) -> None:
    """Mid-execution; lru1 ten minutes away (its state last known); the clock
    `seconds` past its report; the plan's forecast taken then."""
    await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
    far = RobotInfo(name="lru1", online=True, since=T0, heard=T0, delay_s=600.0)
    app.post_message(fleet_changed(far))
    later = T0 + timedelta(seconds=seconds)
    app.clock = lambda: later
    app.model.clock.wall = lambda: later
    await pilot.pause()
    app.plan.refresh(force=True)


async def test_a_distant_robot_is_drawn_where_it_probably_is_now():
    from console.screens.map import MapScreen

    app = make_app()
    async with app.run_test(size=(120, 40)) as pilot:
        await _lru1_far_and_later(app, pilot, seconds=90)
        await pilot.press("f3")
        await wait_until(pilot, lambda: isinstance(app.screen, MapScreen), 10, "map screen")
        await pilot.pause()
        assert app.model.freshness("lru1").stale
        view = app.screen.query_one("MapView")
        view.overlays_changed()
        await pilot.pause()
        text = screen_text(app)
        assert "≈lru1" in text, text


async def test_the_fleet_says_what_a_distant_robot_probably_does_now():
    from console.screens.fleet import FleetScreen

    app = make_app()
    async with app.run_test(size=(140, 40)) as pilot:
        await _lru1_far_and_later(app, pilot, seconds=30)
        await pilot.press("f4")
        await pilot.pause()
        assert isinstance(app.screen, FleetScreen)
        app.screen.query_one("DataTable").move_cursor(row=app.screen.shown.index("lru1"))
        await pilot.pause()
        text = screen_text(app)
        assert "last report:" in text and "≈ now: lru1-2 " in text, text


async def test_the_schedule_header_says_what_a_distant_robot_probably_does_now():
    app = make_app()
    async with app.run_test(size=(140, 40)) as pilot:
        await _lru1_far_and_later(app, pilot, seconds=30)
        await pilot.pause()
        header = screen_text(app).splitlines()[1:4]
        lru1 = [line.split("│")[0] for line in header]
        assert "≈ lru1-2 " in lru1[2], lru1  # the activity line: the probable present
        # the battery as heard; the now-cast's only where it differs (here it does not)
        assert "bat 82%" in lru1[1] and "≈" not in lru1[1], lru1


async def test_the_battery_a_distant_robot_probably_has_now_beside_the_last_heard():
    from console.screens.fleet import FleetScreen

    app = make_app()
    async with app.run_test(size=(160, 40)) as pilot:
        await _lru1_far_and_later(app, pilot, seconds=600)
        nc = robot_nowcast(app.model, "lru1")
        assert nc is not None and nc.battery is not None and f"{nc.battery:.0%}" != "82%"
        now = f"≈{nc.battery:.0%}"
        header = [line.split("│")[0] for line in screen_text(app).splitlines()[1:4]]
        assert f"bat 82% {now}" in header[1], header
        await pilot.press("f4")
        await pilot.pause()
        assert isinstance(app.screen, FleetScreen)
        row = next(line for line in screen_text(app).splitlines() if " lru1 " in line)
        assert f"82% ({now} now)" in row, row
