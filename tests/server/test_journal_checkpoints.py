"""The server checkpoints its journal on a thread, not inside the commit of
whichever operation fills SQLite's write-ahead log (an fsync that held that
operation up for 4-17 ms), and loses nothing by it."""

from __future__ import annotations

import asyncio
import logging
import sqlite3
import threading

from backend.core.ops import EditSkill
from backend.server.journal import Journal

from .harness import serving


def test_the_server_checkpoints_its_journal_off_the_event_loop(tmp_path):
    async def scenario() -> None:
        async with serving(tmp_path / "m.db") as (server, client):
            journal = server.journal
            assert journal.conn.execute("PRAGMA wal_autocheckpoint").fetchone()[0] == 0
            journal.checkpoint_every = 5
            threads = set()
            checkpoint = journal.checkpoint

            def recorded() -> tuple[int, int, int]:
                threads.add(threading.get_ident())
                return checkpoint()

            journal.checkpoint = recorded
            for i in range(12):
                await client.submit(EditSkill(id="lru1-1", label=f"edit {i}"))
                if server._checkpoint is not None:  # the one this operation started
                    await server._checkpoint
            assert journal.checkpoints == 2  # after the 5th and the 10th operation
            assert threads and threading.get_ident() not in threads  # not the event loop's
            revision = server.mission.revision
        with Journal.open(tmp_path / "m.db") as j:
            mission, _ = j.load()
        assert mission.revision == revision and mission.find("lru1-1")[2].label == "edit 11"

    asyncio.run(scenario())


def test_a_checkpoint_that_fails_is_said_once_and_loses_nothing(tmp_path, caplog):
    async def scenario() -> None:
        async with serving(tmp_path / "m.db") as (server, client):
            journal = server.journal
            journal.checkpoint_every = 2
            outcomes = iter(
                [sqlite3.OperationalError("disk I/O error")] * 2
                + [None]
                + [sqlite3.OperationalError("disk I/O error")]
            )
            real = journal.checkpoint

            def flaky() -> tuple[int, int, int]:
                failure = next(outcomes, None)
                if failure is not None:
                    raise failure
                return real()

            journal.checkpoint = flaky
            for i in range(8):
                reply = await client.submit(EditSkill(id="lru1-1", label=f"edit {i}"))
                assert reply.revision == i + 1
                if server._checkpoint is not None:
                    await asyncio.wait([server._checkpoint])

    with caplog.at_level(logging.WARNING, logger="backend.server.server"):
        asyncio.run(scenario())
    said = [r.getMessage() for r in caplog.records if "cannot checkpoint" in r.getMessage()]
    # failed, failed (not said again), succeeded, failed (said again)
    assert len(said) == 2 and "disk I/O error" in said[0] and "nothing is lost" in said[0]
    with Journal.open(tmp_path / "m.db") as j:
        mission, _ = j.load()
    assert mission.revision == 8 and mission.find("lru1-1")[2].label == "edit 7"
