"""What a journal that cannot replay says, word for word: the batch, why,
and how many batches come after it (what `--recover` would set aside)."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest

from backend.core.ops import AddSkill
from backend.core.rules.engine import Engine
from backend.files.missions import load_mission
from backend.server.journal import Journal, JournalCorrupt, Unreplayable

from .harness import ROOT, TUTORIAL


def three_adds(db: Path) -> None:
    mission, library = load_mission(TUTORIAL)
    engine = Engine(mission, library)
    with Journal.open(db, library=str(ROOT / "missions" / "libraries" / "mars.yaml")) as j:
        j.snapshot(engine.mission)
        for label in ("one", "two", "three"):
            op = AddSkill(robot="lru1", skill="recharge", label=label)
            j.record(engine.submit(op, client="ctl", request_id=label), op, client="ctl")


def refusal(db: Path) -> Unreplayable:
    with Journal.open(db) as j, pytest.raises(Unreplayable) as e:
        j.load()
    return e.value


def test_a_missing_batch_names_the_next_one_and_where_replay_stops(tmp_path):
    db = tmp_path / "m.db"
    three_adds(db)
    with sqlite3.connect(db) as conn:
        conn.execute("DELETE FROM batches WHERE revision = 2")
    e = refusal(db)
    assert str(e) == f"{db}: batch 2 is missing (the next one is 3); cannot replay past revision 1"
    assert (e.revision, e.why, e.later, e.what) == (2, "it is missing (the next one is 3)", 1, "")


def test_a_batch_of_another_revision_says_which_it_holds_and_who_wrote_it(tmp_path):
    db = tmp_path / "m.db"
    three_adds(db)
    with sqlite3.connect(db) as conn:
        (text,) = conn.execute("SELECT events FROM batches WHERE revision = 2").fetchone()
        conn.execute(
            "UPDATE batches SET events = ? WHERE revision = 2",
            (json.dumps({**json.loads(text), "revision": 7}),),
        )
    e = refusal(db)
    assert str(e) == f"{db}: batch 2 (add by ctl) cannot be replayed: it says revision 7"
    assert (e.revision, e.why, e.later, e.what) == (2, "it says revision 7", 1, "add by ctl")


def test_a_batch_without_an_actor_is_named_by_its_revision_alone(tmp_path):
    db = tmp_path / "m.db"
    three_adds(db)
    with sqlite3.connect(db) as conn:
        conn.execute("UPDATE batches SET actor = '', events = '{' WHERE revision = 3")
    e = refusal(db)
    assert str(e).startswith(f"{db}: batch 3 cannot be replayed: ")
    assert (e.revision, e.later, e.what) == (3, 0, "")


def test_a_journal_whose_snapshots_all_fail_names_each_and_why(tmp_path):
    db = tmp_path / "m.db"
    three_adds(db)
    with sqlite3.connect(db) as conn:
        (text,) = conn.execute("SELECT mission FROM snapshots WHERE revision = 0").fetchone()
        conn.execute(
            "UPDATE snapshots SET mission = ? WHERE revision = 0",
            (json.dumps({**json.loads(text), "revision": 9}),),
        )
    with Journal.open(db) as j, pytest.raises(JournalCorrupt) as e:
        j.load()
    assert str(e.value) == f"{db}: no snapshot can be read (revision 0: it holds revision 9)"
    with sqlite3.connect(db) as conn:
        conn.execute("DELETE FROM snapshots")
    with Journal.open(db) as j, pytest.raises(JournalCorrupt) as e:
        j.load()
    assert str(e.value) == f"{db}: batches without a base snapshot"


def test_appending_says_what_a_journal_cannot_take(tmp_path):
    db = tmp_path / "m.db"
    three_adds(db)
    with Journal.open(db) as j:
        (record,) = j.records(after=2)
        with pytest.raises(ValueError) as e:
            j.append_many([record.batch])
        assert str(e.value) == (
            "batch revision 3 does not follow the journal's last revision 3 (expected 4): "
            "revisions are consecutive"
        )
        with pytest.raises(ValueError) as e:
            j.append_many([record.batch.model_copy(update={"revision": 4, "events": []})])
        assert str(e.value) == "batch 4 has no events: no-ops are not journaled"
        mission, _ = j.load()
        with pytest.raises(ValueError) as e:
            j.snapshot(mission.model_copy(update={"revision": 5}))
        assert str(e.value) == (
            "cannot snapshot revision 5: the journal ends at revision 3; "
            "append the batches up to it first"
        )
        assert [r.revision for r in j.records()] == [1, 2, 3]
