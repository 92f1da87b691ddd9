"""The SQLite journal: reopening gives back exactly the mission, every skill,
status, barrier, marker and revision; snapshots, fallbacks, request ids."""

from __future__ import annotations

import sqlite3
import sys
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from backend.core.events import EventBatch, SkillEdited, SkillStatusChanged
from backend.core.model import Mission, Pose, PoseMarker, Position, Status
from backend.core.ops import (
    AddBarrier,
    AddSkill,
    DeleteSkills,
    EditSkill,
    LoadMission,
    MarkerAdd,
    MarkerMove,
    MarkerRename,
    MoveSkill,
    NewMission,
    Redo,
    RemoveBarrier,
    Report,
    Retry,
    RetryAck,
    Sync,
    SyncAck,
    Undo,
    Unsync,
    UnsyncDone,
)
from backend.core.rules.engine import Engine, Refusal
from backend.files.missions import load_mission
from backend.server import journal as journal_mod
from backend.server.journal import Entry, Journal, JournalCorrupt, JournalError, remember_requests

sys.path.insert(0, str(Path(__file__).parent))
from crash_worker import OpGenerator, mission_problems  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
MISSION_FILE = ROOT / "tests" / "data" / "mars_sample_return_v1.yaml"
T0 = datetime(2030, 7, 1, 8, 0, tzinfo=UTC)


class Server:
    """An engine whose applied operations are journaled, as the server does."""

    def __init__(
        self, db: Path, *, snapshot_every: int = 500, mission: Mission | None = None, library=None
    ):
        if mission is None:
            mission, library = load_mission(MISSION_FILE)
        self.engine = Engine(mission, library)
        self.library = library
        self.journal = Journal.open(db, library=mission.library, snapshot_every=snapshot_every)
        if self.journal.last_revision() is None:
            self.journal.snapshot(mission)
        self.n = 0
        self.seqs: dict[str, int] = {}
        self.clock = 0

    def submit(self, op, client: str = "alice", *, request_id: str | None = None, **kw):
        self.n += 1
        rid = request_id or f"{client}-{self.n}"
        applied = self.engine.submit(op, client=client, request_id=rid, **kw)
        self.journal.record(applied, op, client=client, request_id=rid, mission=self.engine.mission)
        return applied

    def sync(self, robot: str, through: str | None = None) -> list[str]:
        ids = [s.id for s in self.engine.plan_sync(Sync(robot=robot, through=through))]
        self.submit(SyncAck(robot=robot, ids=ids), f"robot:{robot}")
        self.engine.release(robot, ids)
        return ids

    def report(self, robot: str, sid: str, status: Status, info: str = "", **kw):
        self.seqs[robot] = self.seqs.get(robot, 0) + 1
        self.clock += 1
        op = Report(
            robot=robot,
            seq=self.seqs[robot],
            id=sid,
            status=status,
            info=info,
            at=T0 + timedelta(seconds=30 * self.clock),
            **kw,
        )
        return self.submit(op, f"robot:{robot}")

    def close(self) -> None:
        self.journal.close()


def reopen(db: Path, **kw) -> tuple[Mission | None, list[tuple[str, str, int]], Journal]:
    j = Journal.open(db, **kw)
    mission, requests = j.load()
    return mission, requests, j


def run_scenario(srv: Server) -> dict[str, str]:
    """Every kind of operation an operator and the robots apply; returns the
    generated ids by role."""
    ids: dict[str, str] = {}
    a = srv.submit(
        AddSkill(
            robot="lru1",
            skill="drive_to",
            label="to the crater",
            params={"goal": {"x": 12.5, "y": -3.0, "yaw": 1.2}, "speed": 0.8},
        )
    )
    ids["new1"] = a.value["id"]
    a = srv.submit(
        AddSkill(
            robot="lru2",
            skill="explore",
            params={"max_duration": 120},
            bindings={"area": "ROI-east"},
            at=0,
        ),
        "bob",
    )
    ids["new2"] = a.value["id"]
    a = srv.submit(AddSkill(robot="ardea", skill="fly_to", params={"goal": {"x": 5, "y": 5}}, at=1))
    ids["new3"] = a.value["id"]
    srv.submit(EditSkill(id=ids["new1"], label="to the crater rim", params={"tolerance": 1.5}))
    srv.submit(EditSkill(id="lru1-4", bindings={"target": "POI-B"}), "bob")
    srv.submit(MoveSkill(id=ids["new1"], index=0))
    srv.submit(MoveSkill(id="lru2-6", index=2), "bob")
    srv.submit(DeleteSkills(ids=[ids["new3"]]))
    a = srv.submit(AddBarrier(ids=["lru1-5", "ardea-4", "lander-1"]))
    ids["barrier"] = a.value["barrier"]
    a = srv.submit(AddBarrier(ids=["lru1-4", "ardea-3"]), "bob")
    srv.submit(RemoveBarrier(barrier=a.value["barrier"]), "bob")
    srv.submit(DeleteSkills(ids=["lander-1"]))  # leaves a two-robot barrier
    srv.submit(
        MarkerAdd(
            name="CRATER", marker=PoseMarker(pose=Pose(x=70, y=-20, yaw=0.3), description="rim")
        )
    )
    srv.submit(EditSkill(id=ids["new1"], bindings={"goal": "CRATER"}))
    srv.submit(MarkerMove(name="CRATER", value=Pose(x=72, y=-21)))
    srv.submit(
        MarkerMove(name="ROI-east", value=[Position(x=30), Position(x=90), Position(x=90, y=50)]),
        "bob",
    )
    srv.submit(MarkerRename(name="POI-B", new_name="POI-ridge"))
    # synchronize, then the robots execute
    ids["lru1_synced"] = ",".join(srv.sync("lru1", "lru1-2"))
    srv.sync("lru2", "lru2-3")
    srv.sync("ardea")
    srv.submit(
        MarkerMove(name="POI-A", value=Pose(x=40, y=20))
    )  # synchronized users keep the old value
    first = ids["new1"]
    srv.report("lru1", first, Status.RUNNING, "driving")
    srv.report("lru1", first, Status.PAUSED, "paused")
    srv.report("lru1", first, Status.RUNNING, "resumed")
    srv.report("lru1", first, Status.SUCCESS, "arrived")
    srv.report("lru1", "lru1-1", Status.RUNNING, "driving")
    srv.report("lru1", "lru1-1", Status.FAILURE, "wheel stuck")
    # retry the failed skill: a new attempt right after it
    new = srv.engine.plan_retry(Retry(id="lru1-1"))
    a = srv.submit(RetryAck(robot="lru1", failed_id="lru1-1", skill=new), "robot:lru1")
    srv.engine.release("lru1")
    ids["retry"] = a.value["id"]
    srv.report("lru1", ids["retry"], Status.RUNNING, "driving again", attempt=2)
    srv.report("lru1", ids["retry"], Status.SUCCESS, "arrived")
    srv.report("lru2", ids["new2"], Status.RUNNING)
    srv.report("lru2", ids["new2"], Status.SUCCESS, "mapped")
    srv.report("lru2", "lru2-1", Status.RUNNING)
    srv.report("lru2", "lru2-1", Status.IDLE_SYNCHRONIZED, "stopped")  # stop: back to the queue
    srv.report("ardea", "ardea-1", Status.RUNNING)
    srv.report("ardea", "ardea-1", Status.FAILURE, "rotor fault")
    # unsynchronize the rest of lru2's queue; the robot started lru2-1 meanwhile
    to_take = srv.engine.plan_unsync(Unsync(robot="lru2"))
    assert to_take[0] == "lru2-1"
    srv.report("lru2", "lru2-1", Status.RUNNING, "started before the unsync arrived")
    srv.submit(UnsyncDone(robot="lru2", ids=to_take[1:]), "robot:lru2")
    srv.engine.release("lru2")
    # undo / redo of operator edits
    srv.submit(AddSkill(robot="lru2", skill="recharge", label="top up"), "bob")
    srv.submit(Undo(), "bob")
    srv.submit(Redo(), "bob")
    srv.submit(Undo(), "alice")  # the POI-A move
    # a report sent twice is applied once (and journaled once)
    dup = Report(
        robot="lru1", seq=srv.seqs["lru1"], id=ids["retry"], status=Status.SUCCESS, info="arrived"
    )
    assert srv.engine.submit(dup, client="robot:lru1").duplicate
    return ids


def assert_same(a: Mission, b: Mission) -> None:
    """Field by field first (readable failures), then the whole model."""
    assert a.revision == b.revision
    assert list(a.tasks) == list(b.tasks)
    for robot in b.tasks:
        got = [
            (
                s.id,
                s.status,
                s.status_info,
                s.attempt,
                s.label,
                s.params,
                s.bindings,
                s.policies,
                s.started_at,
                s.finished_at,
                s.rev,
            )
            for s in a.tasks[robot]
        ]
        want = [
            (
                s.id,
                s.status,
                s.status_info,
                s.attempt,
                s.label,
                s.params,
                s.bindings,
                s.policies,
                s.started_at,
                s.finished_at,
                s.rev,
            )
            for s in b.tasks[robot]
        ]
        assert got == want, robot
    assert a.barriers == b.barriers
    assert a.markers == b.markers
    assert (a.task_revs, a.marker_revs, a.report_seqs) == (
        b.task_revs,
        b.marker_revs,
        b.report_seqs,
    )
    assert (a.next_skill, a.next_barrier) == (b.next_skill, b.next_barrier)
    assert a.model_dump() == b.model_dump()
    assert a == b


# -- reopening ------------------------------------------------------------------


@pytest.mark.parametrize("snapshot_every", [500, 4])
def test_reopen_restores_the_mission_after_real_operations(tmp_path, snapshot_every):
    db = tmp_path / "mission.db"
    srv = Server(db, snapshot_every=snapshot_every)
    ids = run_scenario(srv)
    want = srv.engine.mission
    assert not mission_problems(want)
    srv.close()

    mission, _, j = reopen(db)
    with j:
        assert mission is not None
        assert_same(mission, want)
        assert j.last_revision() == want.revision
        if snapshot_every == 4:
            assert j.load_info.snapshot_revision is not None and j.load_info.replayed < 4
            assert len(j.snapshot_revisions()) == 3
        else:
            assert j.load_info.snapshot_revision == 0 and j.load_info.replayed == want.revision

    # the scenario did what it says: spot checks of the restored state
    lru1 = {s.id: s for s in mission.tasks["lru1"]}
    assert lru1[ids["new1"]].status == Status.SUCCESS and lru1[ids["new1"]].bindings == {
        "goal": "CRATER"
    }
    assert lru1[ids["new1"]].params["goal"]["x"] == 72.0
    assert lru1["lru1-1"].status == Status.FAILURE and lru1["lru1-1"].status_info == "wheel stuck"
    assert lru1[ids["retry"]].attempt == 2 and lru1[ids["retry"]].status == Status.SUCCESS
    assert [s.id for s in mission.tasks["lru1"]][:3] == [ids["new1"], "lru1-1", ids["retry"]]
    assert lru1[ids["retry"]].finished_at == T0 + timedelta(seconds=30 * 8)
    assert lru1["lru1-4"].bindings["target"] == "POI-ridge"
    lru2 = {s.id: s for s in mission.tasks["lru2"]}
    assert lru2["lru2-1"].status == Status.RUNNING
    assert all(lru2[i].status == Status.IDLE for i in ("lru2-2", "lru2-3"))
    assert [s.skill for s in mission.tasks["lru2"]][-1] == "recharge"  # redone
    assert mission.tasks["ardea"][0].status == Status.FAILURE
    assert {b: x.skills for b, x in mission.barriers.items()} == {
        "b1": ["lru1-3", "lru2-3"],
        ids["barrier"]: ["lru1-5", "ardea-4"],
    }
    assert set(mission.markers) == {
        "POI-A",
        "POI-ridge",
        "ROI-east",
        "ROI-north",
        "WIFI-1",
        "CRATER",
    }
    assert mission.markers["POI-A"].pose == Pose(x=42.0, y=18.0, yaw=0.4)  # the move was undone
    assert mission.report_seqs == {"lru1": 8, "lru2": 5, "ardea": 2}
    assert ",".join(s for s in ids["lru1_synced"].split(",")) == f"{ids['new1']},lru1-1,lru1-2"


def test_a_restored_mission_keeps_working(tmp_path):
    """After a restart the engine continues on the loaded mission and the
    journal continues at the next revision."""
    db = tmp_path / "mission.db"
    srv = Server(db)
    run_scenario(srv)
    srv.close()
    mission, requests, j = reopen(db)
    _, library = load_mission(MISSION_FILE)
    engine = Engine(mission, library)
    remember_requests(engine, requests)
    before = mission.revision
    a = engine.submit(
        AddSkill(robot="lru1", skill="recharge"), client="alice", request_id="after-restart"
    )
    assert a.revision == before + 1
    assert j.record(
        a, AddSkill(robot="lru1", skill="recharge"), client="alice", request_id="after-restart"
    )
    assert j.last_revision() == a.revision
    j.close()
    again, _, j = reopen(db)
    with j:
        assert again == engine.mission


def test_a_snapshot_waits_until_the_batches_since_add_up_to_half_its_size(tmp_path):
    """A big mission's snapshot costs tens of ms and MBs: after `snapshot_every`
    batches it also waits until they add up to half its size (measured in the
    file, so a reopened journal agrees)."""
    mission, _ = load_mission(MISSION_FILE)
    db = tmp_path / "m.db"
    j = Journal.open(db, snapshot_every=10)
    j.snapshot(mission)

    def sizes() -> tuple[int, int]:
        con = sqlite3.connect(db)
        try:
            snap = con.execute(
                "SELECT length(mission) FROM snapshots ORDER BY revision DESC LIMIT 1"
            ).fetchone()[0]
            since = con.execute(
                "SELECT coalesce(sum(length(op) + length(events)), 0) FROM batches "
                "WHERE revision > (SELECT max(revision) FROM snapshots)"
            ).fetchone()[0]
        finally:
            con.close()
        return snap, since

    deferred = []
    rev = mission.revision
    while True:
        rev += 1
        j.append(
            EventBatch(revision=rev, events=[SkillStatusChanged(id="lru1-1", info="x" * 40)]),
            op_json="{}",
        )
        if rev == mission.revision + 15:  # reopened midway: the same sizes, from the file
            j.close()
            j = Journal.open(db, snapshot_every=10)
            j.load()
        snap, since = sizes()
        want = rev - mission.revision >= 10 and since >= snap / 2
        assert j.snapshot_due(rev) == want, (rev, since, snap)
        if rev - mission.revision >= 10 and not want:
            deferred.append(rev)
        if want:
            break
    assert deferred and rev > mission.revision + 15, (
        f"due at {rev}: after 10 batches or before the reopen"
    )
    assert j.maybe_snapshot(mission.model_copy(update={"revision": rev}))
    assert j.snapshot_revisions()[-1] == rev and not j.snapshot_due(rev + 10)
    j.close()
    # with snapshot_bytes=0, every `snapshot_every` batches whatever their size
    with Journal.open(db, snapshot_every=10, snapshot_bytes=0) as j0:
        assert not j0.snapshot_due(rev + 9) and j0.snapshot_due(rev + 10)


def test_snapshot_plus_replay_equals_full_replay(tmp_path):
    mission, library = load_mission(MISSION_FILE)
    engine = Engine(mission, library)
    full = Journal.open(tmp_path / "full.db", snapshot_every=10**9)
    snap = Journal.open(tmp_path / "snap.db", snapshot_every=37)
    full.snapshot(engine.mission)
    snap.snapshot(engine.mission)

    def commit(st):
        batch = st.applied.batch(st.client)
        for j in (full, snap):
            j.append(
                batch, op_json=st.op.model_dump_json(), client=st.client, request_id=st.request_id
            )
        snap.maybe_snapshot(engine.mission)

    gen = OpGenerator(engine, seed=7, on_step=commit)
    for _ in range(400):
        gen.step()
    assert engine.mission.revision > 200
    full.close()
    snap.close()

    m_full, req_full, jf = reopen(tmp_path / "full.db")
    m_snap, req_snap, js = reopen(tmp_path / "snap.db")
    with jf, js:
        assert jf.load_info.snapshot_revision == 0
        assert jf.load_info.replayed == engine.mission.revision
        assert js.load_info.snapshot_revision > engine.mission.revision - 37
        assert js.load_info.replayed < 37
        assert len(js.snapshot_revisions()) == 3  # older ones pruned
        assert_same(m_snap, m_full)
        assert_same(m_full, engine.mission)
        assert req_full == req_snap


# -- invariants of the journal -------------------------------------------------------


def test_non_consecutive_revisions_are_refused(tmp_path):
    srv = Server(tmp_path / "m.db")
    a = srv.submit(AddSkill(robot="lru1", skill="recharge"))
    j = srv.journal
    assert j.last_revision() == 1
    batch = a.batch("alice")
    with pytest.raises(ValueError, match="revision 1 does not follow .* last revision 1"):
        j.append(batch)  # the same revision twice
    gap = EventBatch(revision=3, events=batch.events)
    with pytest.raises(ValueError, match="expected 2"):
        j.append(gap)
    with pytest.raises(ValueError, match="no events"):
        j.append(EventBatch(revision=2, events=[]))
    # all or nothing: a gap inside append_many writes none of them
    ok = EventBatch(revision=2, events=[SkillEdited(id="lru1-1", label="x")])
    bad = EventBatch(revision=4, events=[SkillEdited(id="lru1-1", label="y")])
    with pytest.raises(ValueError):
        j.append_many([Entry(ok, client="c", request_id="1"), bad])
    assert j.last_revision() == 1
    assert j.append_many([ok, EventBatch(revision=3, events=bad.events)]) == 2
    assert j.last_revision() == 3
    # a snapshot ahead of the journal would hide missing batches
    ahead = srv.engine.mission.model_copy(update={"revision": 9})
    with pytest.raises(ValueError, match="ends at revision 3"):
        j.snapshot(ahead)
    srv.close()


def test_an_empty_journal_loads_nothing_and_needs_a_base(tmp_path):
    with Journal.open(tmp_path / "empty.db", library="libraries/mars.yaml") as j:
        assert j.load() == (None, [])
        assert j.last_revision() is None
        batch = EventBatch(revision=1, events=[SkillEdited(id="a")])
        with pytest.raises(ValueError, match="no base mission"):
            j.append(batch)
        meta = j.meta()
        assert meta["format"] == journal_mod.JOURNAL_FORMAT
        assert j.library == "libraries/mars.yaml"
        datetime.fromisoformat(meta["created"])
        assert j.conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        tables = {r[0] for r in j.conn.execute("SELECT name FROM sqlite_master")}
        assert {"meta", "batches", "snapshots", "batches_request"} <= tables
    with pytest.raises(JournalError, match="closed"):
        j.last_revision()


def test_not_a_journal_is_a_clear_error(tmp_path):
    junk = tmp_path / "junk.db"
    junk.write_bytes(b"this is not SQLite" * 100)
    with pytest.raises(JournalError, match="not a usable journal"):
        Journal.open(junk)
    other = tmp_path / "other.db"
    with Journal.open(other):
        pass
    con = sqlite3.connect(other)
    con.execute("UPDATE meta SET value = 'missionctl/journal@99' WHERE key = 'format'")
    con.commit()
    con.close()
    with pytest.raises(JournalError, match="journal@99"):
        Journal.open(other)
    foreign = tmp_path / "foreign.db"
    con = sqlite3.connect(foreign)
    con.execute("CREATE TABLE people (name TEXT)")
    con.commit()
    con.close()
    with pytest.raises(JournalError, match="not a missionctl journal"):
        Journal.open(foreign)
    assert {r[0] for r in sqlite3.connect(foreign).execute("SELECT name FROM sqlite_master")} == {
        "people"
    }
    with pytest.raises(JournalError, match="no such folder"):
        Journal.open(tmp_path / "missing" / "m.db")


def test_a_journal_locked_by_another_program_at_open_says_so(tmp_path, monkeypatch):
    monkeypatch.setattr(journal_mod, "BUSY_TIMEOUT_S", 0.05)
    db = tmp_path / "m.db"
    with Journal.open(db):
        pass
    other = sqlite3.connect(db, isolation_level=None)
    other.execute("BEGIN EXCLUSIVE")  # e.g. an sqlite3 shell in the middle of a write
    try:
        with pytest.raises(
            JournalError, match="locked by another program .*close it, then start again"
        ):
            Journal.open(db)
    finally:
        other.execute("ROLLBACK")
        other.close()
    with Journal.open(db):  # and it opens once the other program let go
        pass


def test_a_damaged_database_file_is_a_clear_error_not_a_traceback(tmp_path):
    """Pages of the file damaged (disk error, a bad copy): opening or loading
    says so as a JournalCorrupt, never an sqlite3 exception (a traceback at
    the server's start)."""
    db = tmp_path / "m.db"
    srv = Server(db)
    srv.submit(AddSkill(robot="lru1", skill="recharge"))
    srv.close()  # the last connection: the write-ahead log is folded into the file
    con = sqlite3.connect(db)
    page_size = con.execute("PRAGMA page_size").fetchone()[0]
    (root,) = con.execute("SELECT rootpage FROM sqlite_master WHERE name = 'snapshots'").fetchone()
    con.close()
    data = bytearray(db.read_bytes())
    start = (root - 1) * page_size
    data[start : start + page_size] = b"\xab" * page_size
    db.write_bytes(bytes(data))
    with (
        pytest.raises(JournalCorrupt, match="cannot be read .*malformed.*restore a copy"),
        Journal.open(db) as j,
    ):
        j.load()


def test_noops_and_duplicates_are_not_journaled(tmp_path):
    srv = Server(tmp_path / "m.db")
    a = srv.submit(AddSkill(robot="lru1", skill="recharge"), request_id="once")
    rev = srv.journal.last_revision()
    again = srv.engine.submit(
        AddSkill(robot="lru1", skill="recharge"), client="alice", request_id="once"
    )
    assert again.duplicate and again.revision == a.revision
    assert not srv.journal.record(
        again, AddSkill(robot="lru1", skill="recharge"), client="alice", request_id="once"
    )
    noop = srv.engine.submit(MoveSkill(id="lru1-1", index=0))  # already first
    assert not noop.events
    assert not srv.journal.record(noop, MoveSkill(id="lru1-1", index=0))
    assert srv.journal.last_revision() == rev
    srv.close()


def test_robot_reports_are_journaled_with_their_operation(tmp_path):
    srv = Server(tmp_path / "m.db")
    srv.sync("lru1", "lru1-1")
    srv.report("lru1", "lru1-1", Status.RUNNING, "driving")
    srv.report("lru1", "lru1-1", Status.SUCCESS, "arrived")
    records = list(srv.journal.records())
    assert [r.revision for r in records] == [1, 2, 3]
    assert [r.client for r in records] == ["robot:lru1"] * 3
    reports = [Report.model_validate_json(r.op) for r in records[1:]]
    assert [(r.seq, r.status, r.info) for r in reports] == [
        (1, Status.RUNNING, "driving"),
        (2, Status.SUCCESS, "arrived"),
    ]
    assert records[2].batch.op == records[2].op
    assert [r.revision for r in srv.journal.records(after=2)] == [3]
    srv.close()
    mission, _, j = reopen(tmp_path / "m.db")
    with j:
        assert mission.report_seqs == {"lru1": 2}
        assert mission.find("lru1-1")[2].status == Status.SUCCESS


def test_whole_mission_replacements_replay(tmp_path):
    srv = Server(tmp_path / "m.db", snapshot_every=3)
    srv.submit(AddSkill(robot="lru1", skill="recharge"))
    srv.submit(NewMission(name="fresh"))
    srv.submit(AddSkill(robot="lru2", skill="recharge"))
    original, _ = load_mission(MISSION_FILE)
    srv.submit(LoadMission(mission=original))
    srv.submit(DeleteSkills(ids=["lru2-6"]))
    want = srv.engine.mission
    srv.close()
    mission, _, j = reopen(tmp_path / "m.db")
    with j:
        assert_same(mission, want)
        assert mission.name == "Mars sample return"


# -- damaged journals -----------------------------------------------------------------


def _journal_with_snapshots(tmp_path) -> tuple[Path, Mission]:
    db = tmp_path / "m.db"
    mission, library = load_mission(MISSION_FILE)
    engine = Engine(mission, library)
    with Journal.open(db, snapshot_every=25) as j:
        j.snapshot(engine.mission)

        def commit(st):
            j.append(
                st.applied.batch(st.client),
                op_json=st.op.model_dump_json(),
                client=st.client,
                request_id=st.request_id,
            )
            j.maybe_snapshot(engine.mission)

        gen = OpGenerator(engine, seed=3, on_step=commit)
        while engine.mission.revision < 110:
            gen.step()
        assert len(j.snapshot_revisions()) == 3
    return db, engine.mission


def _sql(db: Path, statement: str, *args) -> None:
    con = sqlite3.connect(db)
    con.execute(statement, args)
    con.commit()
    con.close()


@pytest.mark.parametrize(
    "damage",
    [
        '{"format": "missionctl/mission@1", "robots": {',
        '{"library": 3}',
        "not json at all",
        "WRONG_REVISION",
    ],
)
def test_an_unreadable_newest_snapshot_falls_back_to_an_older_one(tmp_path, damage):
    db, want = _journal_with_snapshots(tmp_path)
    with Journal.open(db) as j:
        revs = j.snapshot_revisions()
    if damage == "WRONG_REVISION":
        old = Mission.model_validate_json(
            sqlite3.connect(db)
            .execute("SELECT mission FROM snapshots WHERE revision = ?", (revs[0],))
            .fetchone()[0]
        )
        damage = old.model_dump_json()  # a readable mission, but of another revision
    _sql(db, "UPDATE snapshots SET mission = ? WHERE revision = ?", damage, revs[-1])
    mission, _, j = reopen(db, snapshot_every=25)
    with j:
        assert_same(mission, want)
        assert j.load_info.snapshot_revision == revs[-2]
        assert [r for r, _ in j.load_info.skipped_snapshots] == [revs[-1]]
        # the next snapshot is due counting from the one that could be read
        assert mission.revision - revs[-2] >= 25
        assert j.maybe_snapshot(mission)
        assert j.snapshot_revisions() == [revs[-2], revs[-1], mission.revision]
    mission, _, j = reopen(db)
    with j:
        assert_same(mission, want)
        assert j.load_info.skipped_snapshots == [] and j.load_info.replayed == 0


def test_no_readable_snapshot_or_a_damaged_batch_is_an_error_not_a_partial_mission(tmp_path):
    db, want = _journal_with_snapshots(tmp_path)
    with Journal.open(db) as j:
        revs = j.snapshot_revisions()
    # two damaged: the oldest still works
    for r in revs[1:]:
        _sql(db, "UPDATE snapshots SET mission = '{' WHERE revision = ?", r)
    mission, _, j = reopen(db)
    j.close()
    assert mission == want
    _sql(db, "UPDATE snapshots SET mission = '{' WHERE revision = ?", revs[0])
    with Journal.open(db) as j, pytest.raises(JournalCorrupt, match="no snapshot can be read"):
        j.load()

    (tmp_path / "b").mkdir()
    db2, _ = _journal_with_snapshots(tmp_path / "b")
    with Journal.open(db2) as j:
        newest = j.snapshot_revisions()[-1]
    _sql(db2, "UPDATE batches SET events = '{\"revision\": 1' WHERE revision = ?", newest + 2)
    with (
        Journal.open(db2) as j,
        pytest.raises(JournalCorrupt, match=f"batch {newest + 2} .*cannot be replayed"),
    ):
        j.load()
    _sql(db2, "DELETE FROM batches WHERE revision = ?", newest + 2)
    with (
        Journal.open(db2) as j,
        pytest.raises(JournalCorrupt, match=f"batch {newest + 2} is missing"),
    ):
        j.load()


# -- request ids -------------------------------------------------------------------------


def test_request_ids_survive_a_restart(tmp_path):
    db = tmp_path / "m.db"
    srv = Server(db)
    add = AddSkill(robot="lru1", skill="recharge", label="before the crash")
    a = srv.submit(add, "alice", request_id="req-1")
    b = srv.submit(EditSkill(id=a.value["id"], label="renamed"), "bob", request_id="req-1")
    srv.close()

    mission, requests, j = reopen(db)
    with j:
        assert ("alice", "req-1", a.revision) in [r[:3] for r in requests]
        assert ("bob", "req-1", b.revision) in [r[:3] for r in requests]
        assert requests == sorted(requests, key=lambda r: r[2])
        # the replies too: a retry after the restart gets the same value
        assert requests[0].reply == {"value": {"id": a.value["id"]}, "notes": []}
        assert j.request_revision("alice", "req-1") == a.revision
        assert j.request_revision("alice", "nope") is None
    _, library = load_mission(MISSION_FILE)
    engine = Engine(mission, library)
    remember_requests(engine, requests)
    # the console retries its request after the restart: applied once only
    before = mission.model_copy(deep=True)
    again = engine.submit(add, client="alice", request_id="req-1")
    assert again.duplicate and again.revision == a.revision
    assert again.value == a.value and again.value["id"].startswith("lru1-")
    assert engine.mission == before
    # another client's same request id is another request
    other = engine.submit(add, client="carol", request_id="req-1")
    assert not other.duplicate and other.revision == before.revision + 1


def test_only_the_last_requests_are_returned(tmp_path, monkeypatch):
    monkeypatch.setattr(journal_mod, "REMEMBERED_REQUESTS", 5)
    srv = Server(tmp_path / "m.db")
    for i in range(8):
        srv.submit(AddSkill(robot="lru1", skill="recharge", label=str(i)), request_id=f"r{i}")
    srv.submit(AddSkill(robot="lru1", skill="recharge"), request_id=None)
    srv.close()
    _, requests, j = reopen(tmp_path / "m.db")
    j.close()
    assert [r for _, r, *_ in requests][-5:] == ["r4", "r5", "r6", "r7", "alice-9"]
    assert len(requests) == 5


# -- non-finite numbers ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "payload",
    [
        '{"op": "marker_move", "name": "POI-A", "value": {"x": 1e309, "y": 0}}',
        '{"op": "marker_add", "name": "BAD", '
        '"marker": {"kind": "position", "position": {"x": NaN}}}',
    ],
)
def test_the_engine_refuses_non_finite_marker_coordinates(payload):
    """A pose parameter given directly must be finite ("expected a finite
    number"); the same value reaching it through a marker must be refused too."""
    from pydantic import TypeAdapter, ValidationError

    from backend.core.ops import AnyOp

    mission, library = load_mission(MISSION_FILE)
    engine = Engine(mission, library)
    try:
        op = TypeAdapter(AnyOp).validate_json(payload)
    except ValidationError:
        return  # refused as bad input: correct
    with pytest.raises(Refusal):
        engine.submit(op)


@pytest.mark.parametrize("target", ["finished", "idle"])
def test_robot_reports_cannot_rewrite_the_log_or_unsynchronized_skills(tmp_path, target):
    srv = Server(tmp_path / "m.db")
    srv.sync("lru1", "lru1-2")
    srv.report("lru1", "lru1-1", Status.RUNNING)
    srv.report("lru1", "lru1-1", Status.SUCCESS, "arrived")
    sid, status = ("lru1-1", Status.SUCCESS) if target == "finished" else ("lru1-4", Status.IDLE)
    before = srv.engine.mission.find(sid)[2].model_copy()
    op = Report(
        robot="lru1",
        seq=3,
        id=sid,
        status=status,
        info="rewritten",
        attempt=4,
        at=T0 + timedelta(days=365),
    )
    try:
        srv.engine.submit(op, client="robot:lru1")
    except Refusal:
        pass
    assert srv.engine.mission.find(sid)[2] == before
    srv.close()


# -- checkpoints ----------------------------------------------------------------------------


def _edits(srv: Server, n: int) -> None:
    for i in range(n):
        srv.submit(EditSkill(id="lru1-1", label=f"edit {i}"))


def test_sqlite_checkpoints_inside_commits_unless_the_owner_takes_them_over(tmp_path):
    # 700 operations write well over the 1,000 log pages at which SQLite
    # checkpoints by itself, inside the commit that crosses them
    own = Server(tmp_path / "own.db", snapshot_every=10_000)
    _edits(own, 700)
    busy, log_frames, copied = own.journal.checkpoint()
    assert log_frames < 1000  # SQLite restarted its log after checkpointing on its own
    own.close()

    srv = Server(tmp_path / "m.db", snapshot_every=10_000)
    srv.journal.checkpoint_in_background(every=300)
    assert not srv.journal.checkpoint_due
    _edits(srv, 700)
    assert srv.journal.checkpoint_due
    busy, log_frames, copied = srv.journal.checkpoint()
    assert log_frames >= 1400 and copied == log_frames and busy == 0  # every page since the start
    assert not srv.journal.checkpoint_due and srv.journal.checkpoints == 1
    srv.close()


def test_a_checkpoint_on_another_thread_loses_nothing_the_writer_commits(tmp_path):
    import threading

    srv = Server(tmp_path / "m.db", snapshot_every=10_000)
    srv.journal.checkpoint_in_background(every=1)
    stop = threading.Event()

    def checkpoints() -> None:
        while not stop.is_set():
            srv.journal.checkpoint()

    t = threading.Thread(target=checkpoints)
    t.start()
    try:
        _edits(srv, 400)
    finally:
        stop.set()
        t.join()
    assert srv.journal.checkpoints > 1
    expected = srv.engine.mission
    srv.close()
    mission, _, j = reopen(tmp_path / "m.db")
    assert mission == expected and mission.revision == 400
    j.close()


def test_a_checkpoint_never_creates_a_journal_that_was_deleted(tmp_path):
    db = tmp_path / "m.db"
    srv = Server(db, snapshot_every=10_000)
    srv.journal.checkpoint_in_background()
    _edits(srv, 3)
    for f in tmp_path.glob("m.db*"):
        f.unlink()
    with pytest.raises(JournalError, match="deleted or replaced"):
        srv.journal.checkpoint()
    assert not db.exists()
    srv.close()
    with pytest.raises(JournalError, match="closed"):  # a checkpoint that starts late opens nothing
        srv.journal.checkpoint()


OLD_JOURNAL = Path(__file__).resolve().parents[1] / "data" / "journal_before_typed_events"


def test_a_journal_written_before_typed_events_replays_to_the_same_mission(tmp_path):
    """Written by the code before skill and command events were typed (its
    `skill_changed`/`command_changed` carried a `changes` dict; see make.py
    beside the file): it replays to the mission that code had."""
    db = tmp_path / "old.db"
    db.write_bytes((OLD_JOURNAL / "mission.db").read_bytes())
    raw = sqlite3.connect(db).execute("SELECT events FROM batches").fetchall()
    assert any('"skill_changed"' in r[0] for r in raw)  # the old form, as written
    with Journal.open(db) as j:
        mission, _ = j.load()
    expected = Mission.model_validate_json((OLD_JOURNAL / "mission_after.json").read_text())
    assert mission == expected
    s1, s2 = mission.find("lru1-1")[2], mission.find("lru1-2")[2]
    assert (s1.status, s1.status_info) == (Status.SUCCESS, "arrived")
    assert s1.started_at is not None and s1.finished_at is not None
    assert (s2.status, s2.status_info, s2.label) == (
        Status.FAILURE,
        "wheel stuck",
        "a stone, carefully",
    )
    assert mission.command(1).state == "acked" and mission.command(1).done == ["lru1-1", "lru1-2"]


def test_questions_replay_open_and_answered(tmp_path):
    """A restart keeps a robot's open question (and its answer on its way)
    and the answered one with who answered and what the robot took."""
    from backend.core.model import QuestionState
    from backend.core.ops import Answer, AnswerQuestion, Ask

    db = tmp_path / "mission.db"
    srv = Server(db)
    srv.sync("lru1")
    srv.report("lru1", "lru1-1", Status.RUNNING)

    def ask(ref: str) -> None:
        srv.seqs["lru1"] += 1
        due = T0 + timedelta(hours=1)
        fields = {"text": "search wider?", "choices": ["wider", "give up"], "default": "wider"}
        op = Ask(
            robot="lru1",
            seq=srv.seqs["lru1"],
            ref=ref,
            skill="lru1-1",
            timeout_s=300,
            at=T0,
            due=due,
            **fields,
        )
        srv.submit(op, "robot:lru1")

    ask("a-1")
    srv.engine.clock = lambda: T0 + timedelta(seconds=5)
    taken = srv.submit(AnswerQuestion(question=1, choice="give up"), actor="ann@c1")
    c = srv.engine.mission.command(taken.value["command"])
    srv.seqs["lru1"] += 1
    srv.submit(
        Answer(
            robot="lru1",
            seq=srv.seqs["lru1"],
            command=c.seq,
            outcome="applied",
            at=T0 + timedelta(seconds=9),
        ),
        "robot:lru1",
    )
    ask("a-2")
    srv.submit(AnswerQuestion(question=2, choice="wider"), actor="bob@c2")
    want = srv.engine.mission
    srv.close()

    mission, _, j = reopen(db)
    with j:
        assert mission is not None
        assert_same(mission, want)
        q1, q2 = mission.questions["lru1"]
        assert (q1.state, q1.choice, q1.answered_by) == (
            QuestionState.ANSWERED,
            "give up",
            "ann@c1",
        )
        assert q2.is_open and (q2.answer, q2.answered_by) == ("wider", "bob@c2")
        assert mission.next_question == 3
