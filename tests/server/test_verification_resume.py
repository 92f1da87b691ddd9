"""After a restart the server times a command's started and completed stages
from the forecast its sync was journaled with, as before the restart."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from pathlib import Path

from backend.core.ops import Predicted, Sync
from backend.core.rules.engine import Engine
from backend.files.missions import load_mission
from backend.server.journal import Journal
from backend.server.server import MissionServer
from backend.transport import free_port, loopback_endpoint

from .harness import ROOT, TUTORIAL

T0 = datetime(2030, 7, 1, 8, 0, tzinfo=UTC)


def window(start_s: float, end_s: float) -> Predicted:
    return Predicted(start=T0 + timedelta(seconds=start_s), end=T0 + timedelta(seconds=end_s))


def journal_with_a_sync(db: Path) -> dict[str, Predicted]:
    mission, library = load_mission(TUTORIAL)
    engine = Engine(mission, library)
    ids = [s.id for s in mission.tasks["lru1"]]
    forecast = {sid: window(60 * i, 60 * i + 50) for i, sid in enumerate(ids)}
    other = {"lru1-99": window(0, 1)}  # a skill the mission does not have: not read back
    op = Sync(robot="lru1", forecast={**forecast, **other})
    with Journal.open(db, library=str(ROOT / "missions" / "libraries" / "mars.yaml")) as j:
        j.snapshot(engine.mission)
        j.record(engine.submit(op, client="ctl", request_id="s1"), op, client="ctl")
    return forecast


def test_a_restarted_server_reads_the_syncs_forecasts_back(tmp_path):
    forecast = journal_with_a_sync(tmp_path / "m.db")
    server = MissionServer(db=tmp_path / "m.db", listen=[loopback_endpoint(free_port())])
    try:
        server._load()
        assert server.resumed
        assert server.robot_link.verification.forecasts == forecast
    finally:
        assert server.journal is not None
        server.journal.close()
        if server.archive is not None:
            server.archive.close()
