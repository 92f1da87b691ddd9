"""A clean stop of the server writes the telemetry archive's waiting rows:
the archive writes every few seconds (backend/server/archive.py), a stop
loses none of them."""

from __future__ import annotations

import asyncio
import itertools
from datetime import UTC, datetime

from backend.core.clocks import GROUND
from backend.protocol.archive import ArchiveReader, archive_path
from backend.protocol.messages import Telemetry, dumps
from backend.server.server import MissionServer
from backend.transport import free_port, loopback_endpoint

from .harness import TUTORIAL


class _Msg:
    def __init__(self, payload: bytes) -> None:
        self.payload = payload


def test_a_clean_stop_writes_what_waits_for_the_archives_writer(tmp_path):
    server = MissionServer(
        db=tmp_path / "m.db", mission_file=TUTORIAL, listen=[loopback_endpoint(free_port())]
    )
    server._load()
    archive = server.archive
    assert archive is not None
    archive.flush_s = 3600.0  # nothing written before the stop but by the stop
    ticks = itertools.count()
    archive._clock = lambda: float(next(ticks))  # a second apart: each sample kept
    for k in range(30):
        at = datetime.fromtimestamp(1_000 + k, UTC)
        server._on_telemetry(_Msg(dumps(Telemetry(robot="lru1", at=at))))
    assert archive.kept == 30 and archive.written == 0
    asyncio.run(server.stop())
    assert server.archive is None and archive.written == 30
    with ArchiveReader(archive_path(tmp_path / "m.db")) as r:
        samples = r.last_samples("lru1", 1e12, GROUND, 100)
    assert [s.telemetry.at.timestamp() for s in samples] == [1_000.0 + k for k in range(30)]
