"""`missionctl review`: a recorded mission played into the console's model
(console/state/replay.py, no Textual), the review app on it, and the command.

The recording (tests/files/recorded.py) is made without a network: four
robots, a 60 s link delay, failures retried, telemetry in the archive.
"""

from __future__ import annotations

import gc
import json
from datetime import UTC, datetime

import pytest
from console_state import screen_text, settle, wait_until

from backend.cli.main import main
from backend.core.clocks import GROUND, ROBOT
from backend.core.model import Status
from console.state.model import ConsoleModel
from console.state.replay import parse_goto


@pytest.fixture
def replay(replay_of):
    return replay_of(ConsoleModel())


def _status(model: ConsoleModel, sid: str) -> Status | None:
    found = model.mission.find(sid) if model.mission is not None else None
    return found[2].status if found else None


def test_a_seek_shows_the_mission_as_the_ground_knew_it_or_as_robots_did_it(recorded, replay):
    sid, (robot_t, ground_t) = next(iter(recorded.running.items()))
    replay.seek(robot_t + 1.0)
    assert replay.clock == GROUND and _status(replay.model, sid) != Status.RUNNING
    replay.set_clock(ROBOT)  # the same instant: the robot was running it already
    assert _status(replay.model, sid) == Status.RUNNING
    assert replay.where().startswith("robot time")
    replay.set_clock(GROUND)
    replay.seek(ground_t)
    assert _status(replay.model, sid) == Status.RUNNING
    # the model's clock reads the review's time (ages on every screen)
    assert replay.model.clock() == datetime.fromtimestamp(ground_t, UTC)


def test_steps_go_one_change_at_a_time_and_back(replay):
    replay.seek_revision(40)
    assert replay.model.mission.revision == 40
    position = replay.cursor.position
    replay.step(1)
    assert (replay.cursor.position, replay.model.mission.revision) == (position + 1, 41)
    replay.step(-1)
    assert (replay.cursor.position, replay.model.mission.revision) == (position, 40)


def test_playing_on_from_an_instant_reaches_the_same_end_as_a_seek(recorded, replay):
    replay.seek(recorded.start + 120)
    while not replay.at_end:
        replay.advance(60.0)
    played = replay.model.mission
    replay.seek(replay.span()[1])
    assert played == replay.model.mission and played.revision == replay.journal.last


def _batch_lines(model: ConsoleModel, n: int) -> list[tuple]:
    lines = [e for e in model.log.entries if e.revision is not None]
    return [(e.kind, e.text, e.at, e.robots, e.skill, e.revision) for e in lines[-n:]]


@pytest.mark.parametrize("clock", [GROUND, ROBOT])
def test_a_seeks_log_reads_as_a_console_that_watched_until_then(recorded, replay, clock):
    """A seek builds the state at the instant at once and logs the batches
    before it without applying them again: the same lines, times and robots
    as taking each batch as it came."""
    from console.state.replay import LOG_WINDOW

    replay.set_clock(clock)
    lo, hi = replay.span()
    for t in (lo + (hi - lo) * k / 5 for k in range(1, 6)):
        replay.seek(lo)
        while replay.cursor.at < t:  # played up to t, batch after batch
            replay.advance(min(7.0, t - replay.cursor.at))
        n = min(LOG_WINDOW, replay.cursor.position) // 2
        played, position = _batch_lines(replay.model, n), replay.cursor.position
        replay.seek(t)
        assert replay.cursor.position == position
        assert _batch_lines(replay.model, n) == played, t


def test_a_seek_brings_the_robots_telemetry_alerts_and_the_plan_as_synced(recorded, replay):
    replay.seek(recorded.end)
    assert set(replay.model.telemetry) == {"lru1", "lru2", "ardea", "lander"}
    assert replay.model.alerts.alerts, "the recording raised alerts"
    assert replay.model.log.entries
    # every skill synchronized was sent with a forecast (a retry is not synchronized)
    synced = set(recorded.done) - set(recorded.retried.values())
    assert synced and synced <= set(replay.model.plan.planned)
    replay.seek(recorded.start)
    assert replay.model.plan.planned == {}


def test_a_change_waiting_at_a_seek_applies_when_the_steps_bring_what_it_needs(recorded):
    """lru1's clock two minutes behind: in robot time its answers come before
    the skills they answer were added. A seek in between says they wait; the
    steps that bring the skills let them apply, as the journal's state at
    each position has them (a seek used to leave them out for good)."""
    from backend.files.missions import load_library
    from backend.files.record.journal import JournalReader
    from backend.protocol.archive import ArchiveReader, archive_path
    from console.state.replay import Replay

    with JournalReader(recorded.db) as j, ArchiveReader(archive_path(recorded.db)) as a:
        j.use_index(
            [
                (rev, ts, op, at - 120.0 if robot == "lru1" and at is not None else at, robot)
                for rev, ts, op, at, robot in a.journal_index(j.base)
            ]
        )
        replay = Replay(ConsoleModel(), j, load_library(j.library))
        try:
            replay.set_clock(ROBOT)
            p = next(p for p in range(len(j)) if j.state(p, ROBOT).unplaced)
            replay.seek_position(p)
            assert "not placed in robot time" in replay.where()
            while "not placed" in replay.where():
                assert replay.cursor.position < len(j)
                replay.step(1)
                assert replay.model.mission == j.state(replay.cursor.position, ROBOT).mission
            assert replay.cursor.position > p + 1 and replay.unplaced == []
        finally:
            replay.release()


def test_a_seek_leaves_the_collector_on_and_the_review_gives_back_what_it_froze(
    recorded, replay_of
):
    replay = replay_of(ConsoleModel())
    replay.seek(recorded.end)
    assert gc.isenabled() and gc.get_freeze_count() > 0  # the state, out of its walks
    replay.release()
    assert gc.get_freeze_count() == 0


def test_a_revision_the_journal_does_not_hold_is_said(replay):
    with pytest.raises(ValueError, match="this journal holds 1 to"):
        replay.seek_revision(10**6)


def test_go_to_takes_times_offsets_and_revisions():
    now = datetime(2030, 7, 1, 8, 0, tzinfo=UTC).timestamp()  # TZ=UTC (conftest)
    assert parse_goto("08:30", now) == ("time", now + 1800)
    assert parse_goto("08:30:05", now) == ("time", now + 1805)
    assert parse_goto("+10m", now) == ("time", now + 600)
    assert parse_goto("-30s", now) == ("time", now - 30)
    assert parse_goto("#120", now) == ("revision", 120.0)
    with pytest.raises(ValueError, match="cannot go to 'soon'"):
        parse_goto("soon", now)


def test_the_timeline_draws_the_plan_as_synced_under_the_bars_not_over_links():
    from console.state import timeline as tl

    win = tl.Window(t0=0.0, dt=10.0, width=12)
    cells = tl.spacer({5}, win.width)  # a barrier's link in column 5
    row = "".join(c for c, _ in tl.planned(cells, [(20.0, 80.0), (-50.0, 5.0)], win))
    assert row[0] == "▔" and row[1] == " "  # a span before the window is clipped
    assert row[2:8] == "▔▔▔" + cells[5][0] + "▔▔" and row[8:] == "    "


# -- the review app -----------------------------------------------------------------------------


def review_app(replay_of, **kw):
    """A ReviewApp for tests: no animations, no cursor blink."""
    from console.review.app import ReviewApp

    app = ReviewApp(replay_of, what="mission.db", **kw)
    app.animation_level = "none"
    app.cursor_blink = False
    return app


async def test_the_review_opens_at_the_end_and_steps_goes_to_and_switches_clocks(
    recorded, replay_of
):
    app = review_app(replay_of)
    async with app.run_test(size=(100, 30)) as pilot:
        await settle(pilot)
        last = app.replay.journal.last
        text = screen_text(app)
        assert f"ground time 08:08:55 · {last}/{last} changes (rev {last})" in text
        assert "read-only: review of mission.db" in text and "lru1" in text
        await pilot.press("comma")
        await settle(pilot)
        assert f"{last - 1}/{last} changes (rev {last - 1})" in screen_text(app)
        await pilot.press("full_stop")
        await settle(pilot)
        assert app.model.mission.revision == last
        await pilot.press("g")
        await settle(pilot)
        await pilot.press(*"08:03", "enter")
        await settle(pilot)
        assert "ground time 08:03:00" in screen_text(app)
        assert app.model.mission.revision < last
        await pilot.press("C")
        await settle(pilot)
        assert "robot time 08:03:00" in screen_text(app)
    assert gc.get_freeze_count() == 0  # the review ended: the collector has it all back


async def test_go_to_says_what_it_cannot_read(replay_of):
    app = review_app(replay_of)
    async with app.run_test(size=(100, 30)) as pilot:
        await settle(pilot)
        await pilot.press("g", *"soon", "enter")
        await settle(pilot)
        assert "cannot go to 'soon'" in screen_text(app)
        await pilot.press("escape")
        await settle(pilot)
        assert "ground time 08:08:55" in screen_text(app)


async def test_playing_moves_the_time_on_at_the_chosen_speed(recorded, replay_of):
    app = review_app(replay_of, at=recorded.start)
    async with app.run_test(size=(100, 30)) as pilot:
        await settle(pilot)
        await pilot.press("right_curly_bracket", "right_curly_bracket")
        await settle(pilot)
        assert "paused ×60" in screen_text(app)
        await pilot.press("o")
        await wait_until(pilot, lambda: app.replay.cursor.at > recorded.start, what="playing")
        assert app.playing
        await pilot.press("o")
        await settle(pilot)
        assert "paused ×60" in screen_text(app)


async def test_the_help_lists_the_reviews_keys(replay_of):
    import io

    from rich.console import Console

    from console.screens.dialogs import HelpScreen

    app = review_app(replay_of)
    async with app.run_test(size=(100, 30)) as pilot:
        await settle(pilot)
        await pilot.press("f1")
        await wait_until(pilot, lambda: isinstance(app.screen, HelpScreen), what="help")
        out = Console(width=100, file=io.StringIO(), record=True)
        out.print(app.screen._text())  # all of it, not the part that fits
        text = out.export_text()
        assert "\nReview\n" in text and "Switch between ground time" in text
        assert "review.clock" in text  # its binding id, for the keymap


# -- the command ----------------------------------------------------------------------------------


def test_the_report_lists_plan_against_actual_as_json(recorded, capsys):
    assert main(["review", str(recorded.db), "--report", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert {row["id"] for row in report["skills"]} >= set(recorded.done) - set(
        recorded.retried.values()
    )
    assert main(["review", str(recorded.db), "--report"]) == 0
    assert "Plan against actual" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["--json"], "--json goes with --report"),
        (["--at", "soon"], "--at: cannot go to 'soon'"),
        (["--at", "#999999"], "--at: no revision 999999"),
    ],
)
def test_the_command_says_what_is_wrong(recorded, capsys, argv, says):
    assert main(["review", str(recorded.db), *argv]) == 2
    assert says in capsys.readouterr().err


def test_what_is_not_a_journal_is_said_without_a_traceback(tmp_path, capsys):
    assert main(["review", str(tmp_path / "none.db")]) == 2
    assert "missionctl review: " in capsys.readouterr().err
