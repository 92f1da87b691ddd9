"""The server restarts on any journal it ever wrote.

A journal written before the limits could hold a batch that cannot be
replayed (issue 20: a parameter nested 196 deep, journaled inside its event:
"batch 1 cannot be replayed: Invalid JSON: recursion limit exceeded", and the
server refused to start ever again). Now `missionctl server` says which batch
and offers `--recover`, which keeps everything before it and moves that batch
and the later ones to the journal's quarantine table: never a silent loss,
never a refusal to ever start again.
"""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from backend.core.ops import AddSkill
from backend.core.rules.engine import Engine, Refusal
from backend.files.missions import load_mission
from backend.server.journal import Journal, Unreplayable
from backend.server.server import MissionServer
from backend.transport import free_port, loopback_endpoint

from .harness import ROOT, TUTORIAL, Proc, serving


def written_by_an_older_server(db: Path) -> int:
    """A journal as the server before the limits wrote it: two operations,
    then the issue's add (its parameter nested too deep for the JSON reader)
    and one more batch. Returns the revision of the bad batch."""
    mission, library = load_mission(TUTORIAL)
    engine = Engine(mission, library)
    with Journal.open(db, library=str(ROOT / "missions" / "libraries" / "mars.yaml")) as j:
        j.snapshot(engine.mission)
        for label in ("one", "two"):
            op = AddSkill(robot="lru1", skill="recharge", label=label)
            applied = engine.submit(op, client="ctl", request_id=label)
            j.record(applied, op, client="ctl", request_id=label)
    bad = "[" * 250 + "]" * 250
    events = (
        '{"revision": 3, "events": [{"ev": "skill_changed", "id": "lru1-3", '
        f'"changes": {{"params": {{"camera": {{"a": {bad}}}}}}}}}], "actor": "ctl"}}'
    )
    later = json.dumps({"revision": 4, "events": [{"ev": "report_seq", "robot": "lru1", "seq": 1}]})
    with sqlite3.connect(db) as conn:
        conn.executemany(
            "INSERT INTO batches (revision, ts, actor, client, request_id, op, events) "
            "VALUES (?, 0, 'ctl', 'ctl', ?, ?, ?)",
            [(3, "bad", '{"op": "edit"}', events), (4, None, "report", later)],
        )
    return 3


def server(db: Path, **kw) -> MissionServer:
    return MissionServer(db=db, listen=[loopback_endpoint(free_port())], **kw)


async def test_an_unreplayable_batch_is_named_and_recovered_without_loss(tmp_path):
    db = tmp_path / "m.db"
    bad = written_by_an_older_server(db)
    refused = server(db)
    with pytest.raises(Unreplayable) as e:
        await refused.start()
    assert (e.value.revision, e.value.later) == (bad, 1)
    assert f"batch {bad} (edit by ctl) cannot be replayed" in str(e.value)

    recovering = server(db, recover=True)
    await recovering.start()
    try:
        assert recovering.mission.revision == bad - 1
        assert [s.label for s in recovering.mission.tasks["lru1"][-2:]] == ["one", "two"]
        assert f"batch {bad} (edit by ctl)" in recovering.recovered
        assert "it and the 1 after it are kept" in recovering.recovered
    finally:
        await recovering.stop()
    with sqlite3.connect(db) as conn:
        kept = conn.execute("SELECT kind, revision, request_id FROM quarantine ORDER BY id")
        assert kept.fetchall() == [("batch", 3, "bad"), ("batch", 4, None)]
        assert conn.execute("SELECT max(revision) FROM batches").fetchone() == (2,)

    # it starts again without --recover, and goes on from there
    async with serving(db) as (srv, client):
        assert srv.resumed and srv.recovered is None
        assert srv.engine.requests[("ctl", "one")].value == {"id": "lru1-3"}  # replies kept
        added = await client.submit(AddSkill(robot="lru2", skill="recharge"))
        assert added.revision == bad
    with Journal.open(db) as j:
        assert j.load()[0].revision == bad


def test_the_command_line_offers_the_recovery_then_recovers(tmp_path):
    db = tmp_path / "m.db"
    written_by_an_older_server(db)
    endpoint = loopback_endpoint(free_port())
    args = [sys.executable, "-m", "backend.cli", "server", "--db", str(db), "--listen", endpoint]
    r = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    first, second = r.stderr.splitlines()
    assert first.startswith(f"missionctl server: {db}: batch 3 (edit by ctl) cannot be replayed: ")
    assert "recursion limit exceeded" in first
    assert second == (
        "missionctl server: the mission up to revision 2 replays; to start from it, run again "
        "with --recover: batch 3 and the 1 after it will be kept in the journal's quarantine "
        "table (nothing is deleted)"
    )
    p = Proc([*args, "--recover"])
    try:
        line = p.wait_line("recovered")
        assert f"recovered {db} at revision 2: batch 3 (edit by ctl) cannot be replayed" in line
        assert f"sqlite3 {db} 'SELECT * FROM quarantine'" in line
        p.wait_line("listening on")
    finally:
        p.stop()
    assert p.p.returncode == 0, p.output()


async def test_a_value_the_journal_cannot_read_back_is_refused_not_journaled(tmp_path):
    """What cannot be stored as it is (here a tuple, from code in the server's
    process) is refused before the journal: the mission and the journal are
    unchanged, and the server goes on."""
    async with serving(tmp_path / "m.db") as (srv, _client):
        before = srv.mission.model_copy(deep=True)
        op = AddSkill(
            robot="lru1",
            skill="take_science_image",
            params={"target": {"x": 1, "y": 2}, "camera": {"v": (1, 2)}},
        )
        for bad in ((1, 2), "\ud800"):  # a tuple; a string JSON cannot carry
            bad_op = op.model_copy(update={"params": {**op.params, "camera": {"v": bad}}})
            with pytest.raises(Refusal) as e:
                srv.submit(bad_op, client="in-process")
            assert e.value.code == "not_replayable"
            assert "a restart could not replay it" in e.value.message
        assert srv.mission == before
        assert srv.journal.last_revision() == before.revision
        assert srv.submit(AddSkill(robot="lru1", skill="recharge")).revision == before.revision + 1


def test_a_journal_from_before_replies_were_kept_opens_and_resumes(tmp_path):
    """Its `batches` has no `reply` column (and there is no quarantine): both
    are added when it is opened; its requests are remembered without replies."""
    db = tmp_path / "old.db"
    written_by_an_older_server(db)
    with sqlite3.connect(db) as conn:
        conn.execute("DELETE FROM batches WHERE revision > 2")
        conn.execute("DROP TABLE quarantine")
        conn.execute("ALTER TABLE batches DROP COLUMN reply")
    with Journal.open(db) as j:
        mission, requests = j.load()
    assert mission.revision == 2
    assert [(r.request_id, r.reply) for r in requests] == [("one", None), ("two", None)]
    with sqlite3.connect(db) as conn:
        columns = [row[1] for row in conn.execute("PRAGMA table_info(batches)")]
        assert columns[-1] == "reply"
        assert conn.execute("SELECT count(*) FROM quarantine").fetchone() == (0,)
