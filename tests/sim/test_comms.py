"""The ground link's schedule (sim/comms.py) and its wiring into SimLink."""

from __future__ import annotations

import argparse
from types import SimpleNamespace

import pytest

from sim.comms import CommsWindow, parse_duration, parse_window
from sim.fleet import SimLink


@pytest.mark.parametrize(
    ("text", "seconds"),
    [("500ms", 0.5), ("90s", 90), ("20m", 1200), ("20min", 1200), ("1.5h", 5400), ("2", 2)],
)
def test_durations(text, seconds):
    assert parse_duration(text) == pytest.approx(seconds)


@pytest.mark.parametrize("text", ["", "20 minutes", "-1s", "1d"])
def test_bad_durations_say_the_examples(text):
    with pytest.raises(argparse.ArgumentTypeError, match="20m, 1.5h"):
        parse_duration(text)


def test_a_window_of_20_minutes_every_2_hours():
    w = parse_window("20m/2h")
    assert w == CommsWindow(open_s=1200, period_s=7200)
    assert [w.is_open(t) for t in (0, 1199, 1200, 7199, 7200, 8399, 8400)] == [
        True,
        True,
        False,
        False,
        True,
        True,
        False,
    ]
    assert w.next_change(0) == 1200 and w.next_change(1200) == 7200
    assert w.describe() == "20 min of contact every 2 h (sim time)"


def test_a_window_with_an_offset_opens_later():
    w = parse_window("20m/2h@1h")
    assert not w.is_open(0) and w.is_open(3600) and not w.is_open(3600 + 1200)
    assert w.next_change(0) == 3600
    assert "the first at 1 h" in w.describe()


@pytest.mark.parametrize(
    ("text", "said"),
    [
        ("20m", "OPEN/PERIOD"),
        ("2h/20m", "shorter than the period"),
        ("0s/1h", "longer than 0"),
        ("x/1h", "not a duration"),
    ],
)
def test_bad_windows_say_the_syntax(text, said):
    with pytest.raises(argparse.ArgumentTypeError, match=said):
        parse_window(text)


def test_the_sim_link_follows_sim_time_and_the_window():
    """The delay is sim time (wall = sim / speed); out of the window the robot
    is out of range wherever it is."""
    fleet = SimpleNamespace(link_delay=1200.0, speed=60.0, open=True)
    fleet.ground_open = lambda: fleet.open
    world = SimpleNamespace(in_range=lambda robot: True)
    link = SimLink(world, SimpleNamespace(name="r"), fleet)
    assert link.delay_s == pytest.approx(20.0)  # 20 min at 60x: 20 s of wall time
    assert link.in_range()
    fleet.open = False
    assert not link.in_range()


def test_the_status_tells_the_ground_the_window_for_its_forecasts():
    from sim.status import ground_status
    from sim.world import World
    from sim.worldfile import load_world
    from tests.sim.conftest import WORLD

    world = World(load_world(WORLD), seed=1)
    st = ground_status(world, speed=60.0, link_delay=1200.0, window=parse_window("20m/2h@1h"))
    assert (st.link_delay_s, st.speed) == (1200.0, 60.0)
    w = st.comms_window
    assert w is not None and (w.open_s, w.period_s, w.offset_s) == (1200, 7200, 3600)
    assert ground_status(world, speed=1.0, link_delay=0.0).comms_window is None
