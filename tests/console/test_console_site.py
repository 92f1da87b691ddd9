"""The simulator's score and clock on the top bar (issue 21): from the map
feed, moving on at the sim's speed between messages; no line without a sim."""

from __future__ import annotations

from datetime import timedelta

from console_state import T0, inject, make_app, mars_mid_execution, mars_telemetry, screen_text
from map_state import map_message, mars_snapshot

from console.state.site import SiteClock, sim_clock_text, site_text


def _scored(score: float, sim_time: float):
    snap = mars_snapshot()
    objects = snap.objects.model_copy(update={"score": score})
    return map_message(snap.model_copy(update={"objects": objects, "sim_time": sim_time}))


def test_the_clock_moves_on_at_the_sims_speed_between_messages():
    site = SiteClock(score=1.9, sim_time=1608.0, at=T0, speed=10.0)
    assert site_text(site, T0) == "score 1.9 · sim 26:48"
    assert site_text(site, T0 + timedelta(seconds=6)) == "score 1.9 · sim 27:48"
    still = SiteClock(score=0.0, sim_time=3725.0, at=T0)  # speed not heard yet: it waits
    assert site_text(still, T0 + timedelta(seconds=60)) == "score 0 · sim 1:02:05"
    assert sim_clock_text(-3) == "0:00"


async def test_the_top_bar_shows_the_reported_score_and_the_sim_clock():
    app = make_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        assert "score" not in screen_text(app).splitlines()[0]  # no simulator, no line
        app.post_message(_scored(0.9, 1608.0))
        await pilot.pause()
        await pilot.pause()
        top = screen_text(app).splitlines()[0]
        assert "score 0.9 · sim 26:48" in top, top
        app.post_message(_scored(1.9, 1700.0))  # a stone delivered, reported
        await pilot.pause()
        await pilot.pause()
        assert "score 1.9 · sim 28:20" in screen_text(app).splitlines()[0]


def test_score_and_sim_clock_80x24(snap_compare):
    async def run(pilot):
        app = pilot.app
        await inject(app, pilot, mars_mid_execution(), telemetry=mars_telemetry())
        app.post_message(_scored(0.9, 1608.0))
        await pilot.pause()
        await pilot.pause()
        assert "score 0.9 · sim 26:48" in screen_text(app)

    assert snap_compare(make_app(), terminal_size=(80, 24), run_before=run)
