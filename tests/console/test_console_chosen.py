"""Markers chosen on board on the map and in `ctl state`: a place still to be
chosen says it is an estimate; a chosen one says which robot chose it."""

from __future__ import annotations

from console_state import (
    T0,
    Builder,
    inject,
    make_app,
    mars_telemetry,
    screen_text,
    wait_until,
)
from map_state import map_message

from backend.cli.ctl.render import _marker_lines
from backend.core.model import ChooseRule, Pose, PoseMarker
from backend.core.ops import MarkerAdd, Report
from console.screens.map import MapScreen

SIZE = (160, 40)
RULE = ChooseRule(rank=1, place="approach")


def with_chosen_markers() -> Builder:
    """R1 chosen by lru1 (its report of lru1-1), R2 still to choose."""
    b = Builder()
    for name in ("R1", "R2"):
        b.engine.submit(MarkerAdd(name=name, marker=PoseMarker(pose=Pose(), choose=RULE)))
    b.sync("lru1", "lru1-1")
    b.engine.submit(
        Report(
            robot="lru1",
            seq=1,
            id="lru1-1",
            status="synchwaiting",
            at=T0,
            chosen={"R1": Pose(x=57.0, y=-38.0)},
        )
    )
    return b


def test_ctl_state_says_where_a_place_chosen_on_board_came_from():
    lines = {line.split()[0]: line for line in _marker_lines(with_chosen_markers().mission)[1:]}
    assert "pose (57,-38)  [chosen on board by lru1 (lru1-1)]" in lines["R1"]
    assert "[to be chosen on board (approach of #1 of closest_pair" in lines["R2"]


async def test_the_map_says_which_robot_chose_a_marker_and_which_is_an_estimate():
    b = with_chosen_markers()
    app = make_app()
    async with app.run_test(size=SIZE) as pilot:
        await inject(app, pilot, b, telemetry=mars_telemetry())
        app.post_message(map_message())
        await pilot.press("f3")
        await wait_until(pilot, lambda: isinstance(app.screen, MapScreen), 10, "map")
        screen = app.screen
        screen.select_marker("R1")
        await pilot.pause()
        assert "chosen on board by lru1 (lru1-1)" in screen.message
        assert "chosen on board by lru1" in screen_text(app)
        screen.select_marker("R2")
        await pilot.pause()
        assert "to be chosen on board" in screen.message
        assert "the place shown is an estimate" in screen.message
