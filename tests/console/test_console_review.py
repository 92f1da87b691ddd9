"""`missionctl review`: a recorded mission played into the console's model
(console/state/replay.py, no Textual), the review app on it, and the command.

The recording (tests/files/recorded.py) is made without a network: four
robots, a 60 s link delay, failures retried, telemetry in the archive.
"""

from __future__ import annotations

from datetime import UTC, datetime

import pytest

from backend.core.clocks import GROUND, ROBOT
from backend.core.model import Status
from backend.files.missions import load_library
from backend.files.record.journal import JournalReader
from backend.protocol.archive import ArchiveReader, archive_path
from console.state.model import ConsoleModel
from console.state.replay import Replay, parse_goto
from tests.files.recorded import Recorded, record_mission


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Recorded:
    return record_mission(tmp_path_factory.mktemp("review"))


@pytest.fixture
def replay(recorded):
    with JournalReader(recorded.db) as j, ArchiveReader(archive_path(recorded.db)) as a:
        yield Replay(ConsoleModel(), j, load_library(j.library), a)


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
