"""A recorded mission, read-only: the journal at any instant of either clock,
the telemetry archive (downsampled, bounded, written off the caller's
thread), the plan-against-actual report and the server's history answer."""

from __future__ import annotations

import hashlib
import shutil
import sqlite3
import threading
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from backend.core import events as ev
from backend.core.clocks import GROUND, ROBOT, Order, robot_keys
from backend.core.model import Status
from backend.core.records import RecordError
from backend.files.record.journal import JournalReader, apply_in_order
from backend.files.record.report import plan_against_actual, report_text
from backend.protocol.archive import ArchiveReader, archive_path
from backend.protocol.messages import HistoryRequest, Telemetry
from backend.server import history
from backend.server.archive import TelemetryArchive
from backend.server.journal import Journal

from .recorded import Plan, Recorded, record_mission


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Recorded:
    return record_mission(tmp_path_factory.mktemp("recorded"))


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _status(mission, sid: str) -> Status | None:
    found = mission.find(sid)
    return found[2].status if found else None


# -- the journal ------------------------------------------------------------------------------


def test_reading_never_writes_the_files(recorded, tmp_path):
    db, archive = tmp_path / "copy.db", tmp_path / "copy.telemetry.db"
    shutil.copy(recorded.db, db)
    shutil.copy(recorded.archive, archive)
    before = (_digest(db), _digest(archive))
    with JournalReader(db) as j, ArchiveReader(archive) as a:
        j.state(len(j) // 2, GROUND)
        j.state(len(j), ROBOT)
        a.last_samples("lru1", recorded.end, GROUND, 5)
        with pytest.raises(sqlite3.OperationalError, match="readonly"):
            j._conn.execute("DELETE FROM batches")
    assert (_digest(db), _digest(archive)) == before


def test_the_end_in_ground_time_is_the_mission_the_server_restarts_with(recorded):
    with Journal.open(recorded.db) as journal:
        restarted, _ = journal.load()
    with JournalReader(recorded.db) as j:
        assert len(j) == recorded.ops + recorded.reports
        state = j.state(len(j), GROUND)
    assert state.mission == restarted and state.revision == restarted.revision


def test_every_position_replays_the_journal_prefix(recorded):
    with JournalReader(recorded.db) as j:
        mission = j.snapshot(j.base)
        batches = list(j.batches(j.base + 1, j.last))
        for p in range(0, len(j) + 1, 17):
            expect = mission.copy_deep()
            for b in batches[:p]:
                expect = ev.apply_events(expect, b.batch)
            assert j.state(p, GROUND).mission == expect, p


def test_robot_time_shows_what_a_robot_did_before_the_ground_heard_it(recorded):
    sid, (robot_t, ground_t) = next(iter(recorded.running.items()))
    assert ground_t - robot_t == pytest.approx(Plan().delay_s)
    with JournalReader(recorded.db) as j:
        between = robot_t + 1.0
        assert _status(j.state_at(between, ROBOT).mission, sid) == Status.RUNNING
        assert _status(j.state_at(between, GROUND).mission, sid) != Status.RUNNING
        assert _status(j.state_at(ground_t, GROUND).mission, sid) == Status.RUNNING
        # both clocks end where the journal ends
        assert j.state(len(j), ROBOT).mission.tasks == j.state(len(j), GROUND).mission.tasks


def test_a_state_brings_the_batches_of_its_window_as_taken(tmp_path):
    """`state(p, window=w).recent`: the batches at positions p-w..p-1, those
    held by the snapshot it starts from too (snapshots every 20 batches: every
    window of 30 reaches back over one), each with the batch it was taken with."""
    rec = record_mission(tmp_path, Plan(snapshot_every=20))
    with JournalReader(rec.db) as j:
        assert len(j.snapshot_revisions) > 4
        for clock in (GROUND, ROBOT):
            order = j.order(clock)
            for p in range(0, len(j) + 1, 7):
                state = j.state(p, clock, window=30)
                start = max(0, p - 30)
                window = {j.revision_of(i) for i in order.order[start:p]}
                got = [b.revision for b, _ in state.recent]
                assert len(got) == len(set(got)) and all(
                    start <= order.pos[by] < p for _, by in state.recent
                ), (clock, p)
                if clock == GROUND:
                    assert got == sorted(window)
                    assert all(j.revision_of(by) == b.revision for b, by in state.recent)
                else:  # all but those still waiting; at most a few let in from before
                    assert window - set(state.unplaced) <= set(got), (clock, p)


def test_events_reads_the_batches_pick_does_named_from_the_index(recorded):
    with JournalReader(recorded.db) as j:
        wanted = [len(j) - 1, 0, 5, 5, len(j) // 2]
        picked, events = j.pick(wanted), j.events(iter(wanted))
        assert sorted(events) == sorted(set(wanted)) and j.events([]) == {}
        for i, batch in events.items():
            assert batch == picked[i].batch and batch.op and batch.actor


def test_a_journal_that_lost_its_first_snapshots_starts_at_the_oldest_kept(tmp_path):
    rec = record_mission(tmp_path, Plan(snapshot_every=20))
    with sqlite3.connect(rec.db) as conn:
        revs = [r for (r,) in conn.execute("SELECT revision FROM snapshots ORDER BY revision")]
        assert len(revs) > 3
        conn.execute("DELETE FROM snapshots WHERE revision < ?", (revs[-3],))
    with JournalReader(rec.db) as j:
        assert j.gap and j.base == revs[-3]
        assert j.state(0).revision == revs[-3]


def test_what_is_not_a_journal_is_said(tmp_path):
    with pytest.raises(RecordError, match="no such journal"):
        JournalReader(tmp_path / "none.db")
    other = tmp_path / "other.db"
    with sqlite3.connect(other) as conn:
        conn.execute("CREATE TABLE t (x)")
    with pytest.raises(RecordError, match="not a missionctl journal"):
        JournalReader(other)


def _orders(j: JournalReader) -> dict[str, list[float]]:
    return {clock: list(j.order(clock).keys) for clock in (GROUND, ROBOT)}


def test_the_archives_index_orders_the_journal_as_reading_it_through(recorded):
    """The server's index of the journal (archive) gives the same orders in both
    clocks as the journal read through; a partial index is completed from it."""
    with JournalReader(recorded.db) as plain:
        expect = _orders(plain)
        syncs = plain.syncs()
    with ArchiveReader(archive_path(recorded.db)) as archive:
        rows = archive.journal_index(0)
    assert len(rows) == len(expect[GROUND]) and syncs
    for given in (rows, rows[: len(rows) // 2], []):
        with JournalReader(recorded.db) as j:
            j.use_index(given)
            assert _orders(j) == expect
            assert j.syncs() == syncs


def test_a_missing_batch_is_said_with_its_revision(recorded, tmp_path):
    copy = tmp_path / "copy.db"
    shutil.copy(recorded.db, copy)
    with sqlite3.connect(copy) as conn:
        conn.execute("DELETE FROM batches WHERE revision = 30")
    with JournalReader(copy) as j, pytest.raises(RecordError, match="batch 30 is missing"):
        j.order(GROUND)


# -- the clocks -------------------------------------------------------------------------------


def test_robot_keys_keep_a_robots_order_and_never_pass_the_ground():
    ground = [10.0, 20.0, 30.0, 40.0]
    robot = [None, 15.0, 12.0, 99.0]  # lru1's clock goes back, then runs ahead
    keys = robot_keys(ground, robot, ["alice", "lru1", "lru1", "lru1"])
    assert keys == [10.0, 15.0, 15.0, 40.0]


def test_keys_in_order_need_no_sorting():
    order = Order([1.0, 2.0, 2.0, 5.0])
    assert list(order.order) == list(order.reach) == list(order.nearest) == [0, 1, 2, 3]
    assert order.position_at(2.0) == 3 and order.position_at(0.5) == 0


def test_an_order_plan_applies_exactly_the_first_batches():
    keys = [5.0, 1.0, 7.0, 2.0, 8.0, 3.0, 9.0, 4.0]
    order = Order(keys)
    snapshots = [-1, 1, 3, 5]
    for p in range(len(keys) + 1):
        plan = order.plan(p, snapshots)
        held = set(range(plan.snapshot + 1))
        assert held <= set(order.order[:p])
        assert held | set(plan.apply) == set(order.order[:p])
        assert plan.apply == sorted(plan.apply, key=order.pos.__getitem__)


def test_a_batch_that_cannot_apply_yet_waits_for_what_it_needs(recorded):
    with JournalReader(recorded.db) as j:
        batches = list(j.batches(j.base + 1, j.last))
        mission = j.snapshot(j.base)
        add = next(i for i, b in enumerate(batches) if b.name == "add")
        edit = next(i for i, b in enumerate(batches) if b.name == "edit")
        ahead = [*batches[:add], batches[edit], *batches[add:edit], *batches[edit + 1 :]]
        left: list[int] = []
        taken: list = []
        done = apply_in_order(mission, [b.batch for b in ahead], left, taken)
        assert left == [] and done == j.state(len(j)).mission
        # the edit was taken right after the add that made it apply, with that add
        k = next(k for k, (b, _) in enumerate(taken) if b is batches[edit].batch)
        by = taken[k - 1][0]
        assert by.op == "add" and taken[k][1] == by.revision < batches[edit].revision


# -- the archive ------------------------------------------------------------------------------


def _sample(robot: str, at: float, mode: str = "idle") -> Telemetry:
    return Telemetry(robot=robot, mode=mode, at=datetime.fromtimestamp(at, UTC))


def test_the_archive_keeps_a_sample_a_second_and_every_change(tmp_path):
    clock = [0.0]
    archive = TelemetryArchive(tmp_path / "a.telemetry.db", clock=lambda: clock[0])
    archive.start()
    try:
        kept = []
        for k in range(40):  # 10 s at 4 Hz
            clock[0] = k * 0.25
            mode = "executing" if k >= 9 else "idle"
            kept.append(archive.took(_sample("lru1", 1000 + clock[0], mode), received=clock[0]))
        for k in range(40):  # a mode flapping at 100 Hz: at most 10 a second
            clock[0] = 20 + k * 0.01
            archive.took(_sample("lru2", 2000 + k, "a" if k % 2 else "b"), received=clock[0])
    finally:
        archive.close()
    assert kept[0] and kept[9]  # the first, and the change of mode (at 2.25 s) at once
    assert sum(kept) == 11  # 0, 1, 2 s; then 2.25, 3.25 ... 9.25 s
    with ArchiveReader(archive.path) as r:
        assert len(r.last_samples("lru2", 1e9, GROUND, 100)) <= 5
        lru1 = r.last_samples("lru1", 1e9, ROBOT, 100)
        assert [s.telemetry.mode for s in lru1] == ["idle"] * 3 + ["executing"] * 8


def test_the_archive_reads_its_span_ranges_and_levels_as_its_table_holds_them(recorded):
    """span, samples and last_levels read each robot's index, not the table:
    the same answers as statements over the whole table (ties of a time in
    the robots' order)."""
    with ArchiveReader(recorded.archive) as r, sqlite3.connect(recorded.archive) as conn:
        rank = {robot: k for k, robot in enumerate(r.robots)}
        for clock, col in ((GROUND, "received"), (ROBOT, "at")):
            lo, hi = conn.execute(f"SELECT min({col}), max({col}) FROM telemetry").fetchone()
            assert r.span(clock) == (lo, hi)
            after, upto = lo + 10.0, (lo + hi) / 2
            rows = conn.execute(
                f"SELECT robot, {col} FROM telemetry WHERE {col} > ? AND {col} <= ?",
                (after, upto),
            ).fetchall()
            got = [(s.telemetry.robot, s.at) for s in r.samples(after, upto, clock)]
            assert got == sorted(rows, key=lambda row: (row[1], rank[row[0]]))
            assert len(got) > len(set(t for _, t in got))  # robots' samples at one time
            for robot in r.robots:
                samples = r.last_samples(robot, upto, clock, 120)
                levels = [(s.telemetry.battery, s.telemetry.link) for s in samples]
                assert len(levels) == 120 and r.last_levels(robot, upto, clock, 120) == levels


def test_an_archive_without_samples_has_no_span(tmp_path):
    archive = TelemetryArchive(tmp_path / "h.telemetry.db")
    archive.start()
    archive.close()
    with ArchiveReader(archive.path) as r:
        assert r.span(GROUND) is None and r.span(ROBOT) is None
        assert list(r.samples(-1e18, 1e18, GROUND)) == []


def test_the_archive_writes_every_sample_taken_as_it_was(tmp_path):
    """Samples go in several to a statement (ROWS_A_STATEMENT): a number of
    them that is no multiple of it, each read back as it was taken."""
    from backend.server.archive import ROWS_A_STATEMENT

    archive = TelemetryArchive(tmp_path / "e.telemetry.db", every_s=0.0)
    archive.start()
    n = 2 * ROWS_A_STATEMENT + 23
    taken = [
        _sample("lru1", float(k), mode="executing" if k % 3 else "idle").model_copy(
            update={"battery": k / n, "skill": f"lru1-{k}" if k % 2 else None}
        )
        for k in range(n)
    ]
    try:
        for k, t in enumerate(taken):
            archive._clock = lambda k=k: k * 1.0
            assert archive.took(t, received=1000.0 + k)
        assert archive.flush()
    finally:
        archive.close()
    with ArchiveReader(archive.path) as r:
        back = r.last_samples("lru1", 1e9, GROUND, 10 * n)
    assert [s.at for s in back] == [1000.0 + k for k in range(n)]
    assert [s.telemetry for s in back] == taken


def test_the_archive_keeps_the_newest_samples_only(tmp_path):
    archive = TelemetryArchive(tmp_path / "b.telemetry.db", every_s=0.0, max_samples=50)
    archive.start()
    try:
        for k in range(200):
            archive._clock = lambda k=k: k * 1.0
            archive.took(_sample("lru1", float(k)), received=float(k))
    finally:
        archive.close()
    with ArchiveReader(archive.path) as r:
        samples = r.last_samples("lru1", 1e9, GROUND, 1000)
    assert len(samples) == 50 and samples[-1].at == 199.0


def test_a_recording_faster_than_any_robot_flushes_and_loses_nothing(tmp_path):
    from backend.server.archive import QUEUE_MAX

    archive = TelemetryArchive(tmp_path / "d.telemetry.db", every_s=0.0, flush_s=60.0)
    archive.start()
    n = 3 * QUEUE_MAX
    try:
        for k in range(n):
            archive._clock = lambda k=k: k * 1.0
            assert archive.took(_sample("lru1", float(k)), received=float(k))
            if k % (QUEUE_MAX // 2) == 0:
                assert archive.flush()  # written, though flush_s is a minute
                assert archive.written == k + 1
    finally:
        archive.close(timeout=60)
    assert archive.dropped == 0 and archive.written == n


def test_taking_a_sample_never_waits_for_the_disk(tmp_path):
    archive = TelemetryArchive(tmp_path / "c.telemetry.db", every_s=0.0)
    archive.start()
    blocked = threading.Event()
    release = threading.Event()
    real = archive._commit

    def slow(*a, **kw):  # the writer is held up, as by a slow disk
        blocked.set()
        release.wait(10)
        return real(*a, **kw)

    archive._commit = slow
    try:
        archive._clock = lambda: 0.0
        archive.took(_sample("lru1", 0.0), received=0.0)
        assert blocked.wait(10)
        for k in range(1, 500):  # all taken while the writer waits
            archive._clock = lambda k=k: k * 1.0
            assert archive.took(_sample("lru1", float(k)), received=float(k))
    finally:
        release.set()
        archive.close()
    with ArchiveReader(archive.path) as r:
        assert len(r.last_samples("lru1", 1e9, GROUND, 1000)) == 500


def _held(archive: TelemetryArchive) -> tuple[threading.Event, threading.Event]:
    """The writer held up in its next commit, as by a slow disk: (it is held, let it go)."""
    blocked, release = threading.Event(), threading.Event()
    real = archive._commit

    def slow(*a, **kw):
        blocked.set()
        release.wait(10)
        return real(*a, **kw)

    archive._commit = slow
    return blocked, release


def test_a_full_queue_drops_what_comes_counts_it_and_says_it_once(tmp_path, monkeypatch, caplog):
    import logging

    import backend.server.archive as module

    monkeypatch.setattr(module, "QUEUE_MAX", 100)
    archive = TelemetryArchive(tmp_path / "f.telemetry.db", every_s=0.0)
    archive.start()
    blocked, release = _held(archive)
    taken = []
    try:
        with caplog.at_level(logging.WARNING, logger=module.__name__):
            archive._clock = lambda: 0.0
            assert archive.took(_sample("lru1", 0.0), received=0.0)
            assert blocked.wait(10)  # the writer has the first and waits for the disk
            for k in range(1, 131):  # 100 wait for it, the 30 after them are dropped
                archive._clock = lambda k=k: k * 1.0
                taken.append(archive.took(_sample("lru1", float(k)), received=float(k)))
    finally:
        release.set()
        archive.close()
    assert taken == [True] * 100 + [False] * 30
    assert (archive.kept, archive.dropped, archive.written) == (101, 30, 101)
    said = [r.getMessage() for r in caplog.records if "cannot keep up" in r.getMessage()]
    assert len(said) == 1 and "f.telemetry.db" in said[0]
    with ArchiveReader(archive.path) as r:
        assert [s.at for s in r.last_samples("lru1", 1e9, GROUND, 1000)] == list(range(101))


def test_an_archive_that_cannot_write_says_why_and_never_holds_anyone_up(tmp_path):
    archive = TelemetryArchive(tmp_path / "g.telemetry.db", every_s=0.0)
    archive.start()

    def full(*a, **kw):
        raise sqlite3.OperationalError("database or disk is full")

    archive._insert = full
    try:
        archive._clock = lambda: 0.0
        assert archive.took(_sample("lru1", 0.0), received=0.0)
        assert not archive.flush(timeout=0.2)  # never written: the flush says so
        assert archive.failed == "database or disk is full"
        for k in range(1, 50):  # still taken, and left out: nobody waits for it
            archive._clock = lambda k=k: k * 1.0
            assert archive.took(_sample("lru1", float(k)), received=float(k))
    finally:
        thread = archive._thread
        archive.close()
    assert thread is not None and not thread.is_alive()
    assert archive.written == 0 and not archive._queue  # what came later was taken


def test_the_archive_is_named_after_the_journal():
    assert archive_path("/x/mission.db") == Path("/x/mission.telemetry.db")
    assert archive_path("journal") == Path("journal.telemetry.db")


# -- the report and the history -----------------------------------------------------------------


def test_the_report_has_plan_against_actual_for_every_synchronized_skill(recorded):
    with JournalReader(recorded.db) as j:
        report = plan_against_actual(j)
    rows = {r.id: r for r in report.skills}
    done = {sid for sid in recorded.done if "." not in sid}  # first attempts
    assert done | set(recorded.failed) <= set(rows)
    for sid, (start, end) in recorded.done.items():
        row = rows[sid]
        assert (row.started.timestamp(), row.finished.timestamp()) == (start, end)
        if "." not in sid:  # synchronized with a forecast (a retry is not)
            assert row.predicted_start is not None and row.start_late_s is not None
            assert row.synchronized_by == "alice@console-a"
    for sid in recorded.failed:
        assert rows[sid].failures == ["stuck"]
        assert rows[sid].retried_as == recorded.retried[sid]
        assert rows[recorded.retried[sid]].retry_of == sid
    assert [w.check for w in report.waivers] == recorded.waived
    assert report.overdue == [] and "do not exist yet" in report.overdue_note
    actors = {a.actor: a.operations for a in report.actors}
    assert actors["alice@console-a"]["sync"] == 4 * Plan().cycles
    assert actors["lru1"]["report"] > 0
    text = report_text(report)
    assert "Overdue verifications: none listed" in text and "Who did what" in text


def test_history_filters_by_robot_user_and_time(recorded):
    with Journal.open(recorded.db) as journal:
        mission, _ = journal.load()
    owners = {s.id: r for r, task in mission.tasks.items() for s in task}
    everything = history.answer(recorded.db, HistoryRequest(limit=10_000), owners)
    assert len(everything.entries) == recorded.ops + recorded.reports and not everything.more
    revisions = [e.revision for e in everything.entries]
    assert revisions == sorted(revisions)

    alice = history.answer(recorded.db, HistoryRequest(user="alice", limit=10_000), owners)
    assert alice.entries and {e.user for e in alice.entries} == {"alice"}
    assert {e.client for e in alice.entries} == {"console-a"}

    lru2 = history.answer(recorded.db, HistoryRequest(robot="lru2", limit=10_000), owners)
    assert all("lru2" in e.robots for e in lru2.entries)
    ops = {e.op for e in lru2.entries}
    assert {"add", "sync", "report", "answer", "uplink_sent"} <= ops

    late = datetime.fromtimestamp(recorded.end, UTC) - timedelta(seconds=60)
    recent = history.answer(recorded.db, HistoryRequest(since=late, limit=10_000), owners)
    assert recent.entries and all(e.at >= late for e in recent.entries)

    newest = history.answer(recorded.db, HistoryRequest(limit=5), owners)
    assert newest.more and [e.revision for e in newest.entries] == revisions[-5:]


_FORMAT_1 = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE telemetry (
    id INTEGER PRIMARY KEY, robot TEXT NOT NULL, at REAL NOT NULL, received REAL NOT NULL,
    x REAL, y REAL, z REAL, roll REAL, pitch REAL, yaw REAL,
    battery REAL, link REAL, in_range INTEGER,
    mode TEXT, skill TEXT, progress REAL, eta_s REAL, info TEXT
);
CREATE INDEX telemetry_ground ON telemetry (robot, received);
CREATE INDEX telemetry_robot ON telemetry (robot, at);
CREATE TABLE notes (
    id INTEGER PRIMARY KEY, kind TEXT NOT NULL, at REAL NOT NULL, body TEXT NOT NULL
);
INSERT INTO meta VALUES ('format', 'missionctl/telemetry-archive@1');
"""


def test_an_archive_of_the_first_format_reads_as_ever(tmp_path):
    """@1 (before `recent`): its samples in both clocks, its span; a server
    that opens it again makes it @2 and keeps them."""
    from backend.protocol.archive import ARCHIVE_FORMAT, SAMPLE_COLUMNS, sample_row

    path = tmp_path / "old.telemetry.db"
    with sqlite3.connect(path) as conn:
        conn.executescript(_FORMAT_1)
        for k in range(5):
            row = sample_row(_sample("lru1", 1000.0 + k), 2000.0 + k)
            conn.execute(
                f"INSERT INTO telemetry ({SAMPLE_COLUMNS}) VALUES ({', '.join('?' * 17)})", row
            )
    conn.close()
    with ArchiveReader(path) as r:
        assert r.robots == ["lru1"] and r.span(GROUND) == (2000.0, 2004.0)
        assert [s.at for s in r.last_samples("lru1", 1002.0, ROBOT, 2)] == [1001.0, 1002.0]
        assert [s.at for s in r.samples(2001.0, 2003.0, GROUND)] == [2002.0, 2003.0]
    archive = TelemetryArchive(path, every_s=0.0)
    archive.start()
    archive.close()
    with ArchiveReader(path) as r:
        assert r.meta["format"] == ARCHIVE_FORMAT and r.span(ROBOT) == (1000.0, 1004.0)


def test_the_newest_samples_read_before_they_are_moved_and_after(tmp_path, monkeypatch):
    """A live archive's samples wait in `recent` until MOVE_AT do: a review
    reads them there as in `telemetry`; a clean stop moves them all."""
    import backend.server.archive as writer

    monkeypatch.setattr(writer, "MOVE_AT", 10)
    archive = TelemetryArchive(tmp_path / "m.telemetry.db", every_s=0.0, max_samples=12)
    archive.start()
    try:
        for k in range(24):
            archive._clock = lambda k=k: k * 1.0
            archive.took(_sample("lru1", 1000.0 + k), received=2000.0 + k)
            if k == 14:  # a write of 15: moved
                assert archive.flush()
        assert archive.flush()  # a write of 9 more: waiting, to move at the next
        with ArchiveReader(archive.path) as r, sqlite3.connect(archive.path) as conn:
            waiting = conn.execute("SELECT count(*) FROM recent").fetchone()[0]
            assert waiting == 9
            got = [s.at for s in r.last_samples("lru1", 1e9, GROUND, 100)]
            assert got[-1] == 2023.0 and got == sorted(got) and len(got) <= 12 + 10
            assert r.span(ROBOT)[1] == 1023.0
            assert [s.at for s in r.samples(2019.0, 2023.0, GROUND)] == [
                2020.0,
                2021.0,
                2022.0,
                2023.0,
            ]
            assert r.last_levels("lru1", 1e9, GROUND, 3) == [(1.0, 1.0)] * 3
    finally:
        archive.close()
    with ArchiveReader(archive.path) as r, sqlite3.connect(archive.path) as conn:
        assert conn.execute("SELECT count(*) FROM recent").fetchone()[0] == 0
        assert [s.at for s in r.last_samples("lru1", 1e9, GROUND, 100)] == [
            2012.0 + k for k in range(12)
        ]
