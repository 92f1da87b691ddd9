"""Which skill library a server resuming a journal loads, and what it says
when it cannot tell."""

from __future__ import annotations

import pytest

from backend.files.missions import load_mission
from backend.server.journal import Journal
from backend.server.server import MissionServer
from backend.transport import free_port, loopback_endpoint

from .harness import TUTORIAL


def test_a_journal_naming_no_library_and_no_mission_file_is_said(tmp_path):
    db = tmp_path / "m.db"
    mission, _ = load_mission(TUTORIAL)
    with Journal.open(db) as j:
        j.snapshot(mission)
    server = MissionServer(db=db, listen=[loopback_endpoint(free_port())])
    with pytest.raises(SystemExit) as e:
        server._load()
    assert str(e.value) == f"{db}: the journal does not say which skill library it uses"


def test_a_journal_naming_no_library_takes_the_mission_files(tmp_path):
    db = tmp_path / "m.db"
    mission, _ = load_mission(TUTORIAL)
    with Journal.open(db) as j:
        j.snapshot(mission)
    server = MissionServer(
        db=db, mission_file=TUTORIAL, listen=[loopback_endpoint(free_port())], archive_samples=0
    )
    server._load()
    try:
        assert server.resumed and server.library_file == TUTORIAL.parent / mission.library
    finally:
        server.journal.close()
