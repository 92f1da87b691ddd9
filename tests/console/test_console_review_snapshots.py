"""Snapshots of `missionctl review` on a recorded mission (tests/files/recorded.py,
deterministic: fixed times, no network): the schedule in robot time at 80x24,
the timeline with the plan as synchronized under what happened at 120x40 (just
after a sync, and fitted to the whole mission once skills finished), and
the map at 80x24. Each asserts real content first. Every SVG was looked at.
Update with: pytest tests/console/test_console_review_snapshots.py --snapshot-update
"""

from __future__ import annotations

from console_state import screen_text, settle
from test_console_review import review_app

from backend.core.clocks import GROUND
from backend.files.record.journal import JournalReader


def _shows(app, *needles):
    text = screen_text(app)
    for needle in needles:
        assert needle in text, f"{needle!r} not on screen:\n{text}"


def test_review_schedule_in_robot_time_80x24(snap_compare, recorded, replay_of):
    app = review_app(replay_of, at=recorded.start + 300)

    async def run(pilot):
        await settle(pilot)
        await pilot.press("C")
        await settle(pilot)
        pilot.app.clear_notifications()
        await settle(pilot)
        _shows(pilot.app, "robot time 08:05:00", "lru1", "review of mission.db")
        text = screen_text(pilot.app)  # a recording: no connection, no key to cancel
        assert "offline" not in text and "cancels it" not in text, text
        assert "waiting for lru1's answer" in text

    assert snap_compare(app, terminal_size=(80, 24), run_before=run)


def test_review_timeline_planned_under_actual_120x40(snap_compare, recorded, replay_of):
    with JournalReader(recorded.db) as j:  # just after the third sync: skills planned ahead
        index, _ = j.syncs()[2]
        at = j.order(GROUND).keys[index] + 1.0
    app = review_app(replay_of, at=at)

    async def run(pilot):
        await settle(pilot)
        await pilot.press("f7")
        await settle(pilot)
        pilot.app.clear_notifications()
        await settle(pilot)
        _shows(pilot.app, "▔ as planned at sync", "▔▔")

    assert snap_compare(app, terminal_size=(120, 40), run_before=run)


def test_review_timeline_actual_over_planned_120x40(snap_compare, recorded, replay_of):
    app = review_app(replay_of, at=recorded.start + 300)

    async def run(pilot):
        await settle(pilot)
        await pilot.press("f7")
        await settle(pilot)
        await pilot.press("0")  # fit: what happened, then the plan
        await settle(pilot)
        pilot.app.clear_notifications()
        await settle(pilot)
        lines = screen_text(pilot.app).splitlines()
        lane = next(i for i, line in enumerate(lines) if line.startswith("lru1 "))
        done = lines[lane].index("✓")  # the first finished skill, at its actual time
        assert lines[lane + 1][done] == "▔", "the plan as synced runs under what happened"

    assert snap_compare(app, terminal_size=(120, 40), run_before=run)


def test_review_map_80x24(snap_compare, replay_of):
    app = review_app(replay_of)

    async def run(pilot):
        await settle(pilot)
        await pilot.press("f3")
        await settle(pilot)
        pilot.app.clear_notifications()
        await settle(pilot)
        _shows(pilot.app, "review: markers and goals from the journal")

    assert snap_compare(app, terminal_size=(80, 24), run_before=run)


def test_review_go_to_with_a_mistake_80x24(snap_compare, replay_of):
    app = review_app(replay_of)

    async def run(pilot):
        await settle(pilot)
        await pilot.press("g", *"14h", "enter")
        await settle(pilot)
        _shows(pilot.app, "Go to (ground)", "cannot go to '14h'", "#120 (a revision)")

    assert snap_compare(app, terminal_size=(80, 24), run_before=run)
