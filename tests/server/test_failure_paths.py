"""Failure paths of the server. The journal cannot be written (disk full,
locked by another program, deleted under the server): an operation or a
robot report is refused and changes nothing, in memory or after a restart,
and is applied once the journal works again. A second server on the same
journal is refused. A request whose reply is lost (server restarted or gone)
can be retried with its request id and is applied once.

The server runs in the test process (its journal's connection is replaced
by one that fails like a full disk); the client and the robot agent are on
the same event loop with their own Zenoh sessions, closed in teardown."""

from __future__ import annotations

import asyncio
import sqlite3
import subprocess
import sys
import threading

import pytest

from backend.agent import RobotAgent
from backend.client.client import MissionClient, OperationRefused, ServerGone, ServerUnreachable
from backend.client.events import AlertRaised
from backend.core.ops import AddSkill, Control, Sync, Undo, Unsync
from backend.server.journal import Journal, JournalError
from backend.transport import free_port, loopback_endpoint

from .harness import ROOT, TUTORIAL, Proc, new_server, serving, status

pytestmark = pytest.mark.timeout(120)

WAIT = 15.0


class FullDisk:
    """Stands in for the journal's SQLite connection: writes fail as on a full
    disk (and are counted), reads go through."""

    def __init__(self, conn: sqlite3.Connection):
        self.conn = conn
        self.refused = 0
        self.tried = threading.Event()

    def execute(self, sql: str, *args):
        if sql.lstrip().upper().startswith(("INSERT", "BEGIN IMMEDIATE", "UPDATE", "DELETE")):
            self.refused += 1
            self.tried.set()
            raise sqlite3.OperationalError("database or disk is full")
        return self.conn.execute(sql, *args)

    def __getattr__(self, name: str):
        return getattr(self.conn, name)


async def restarted(db) -> str:
    """The mission as a server restarted on `db` has it (JSON)."""
    server = new_server(db, loopback_endpoint(free_port()))
    await server.start()
    try:
        return server.mission.model_dump_json()
    finally:
        await server.stop()


def drive_to(label: str = "") -> AddSkill:
    return AddSkill(
        robot="lru1", skill="drive_to", label=label, params={"goal": {"x": 1, "y": 2, "yaw": 0}}
    )


def test_an_operation_the_journal_cannot_take_is_refused_and_changes_nothing(tmp_path):
    db = tmp_path / "m.db"

    async def scenario():
        async with serving(db) as (server, client):
            alerts = []
            client.add_listener(
                lambda e: alerts.append(e.alert) if isinstance(e, AlertRaised) else None
            )
            before = server.mission.model_dump_json()
            real = server.journal._conn
            server.journal._conn = FullDisk(real)
            with pytest.raises(OperationRefused) as refused:
                await client.submit(drive_to("full"), request_id="a1")
            err = refused.value
            assert err.code == "journal_failed"
            assert (
                str(db) in str(err)
                and "disk is full" in str(err)
                and "the mission was not changed" in str(err)
            )
            assert "free disk space" in str(err)
            assert server.mission.model_dump_json() == before  # not applied in memory either
            await client.wait_for(lambda m: any(a.kind == "journal" for a in alerts), WAIT)
            assert client.revision == 0

            server.journal._conn = real  # space freed: the same request is applied now, once
            reply = await client.submit(drive_to("full"), request_id="a1")
            assert not reply.duplicate and reply.revision == 1
            again = await client.submit(drive_to("full"), request_id="a1")
            assert again.duplicate and again.revision == 1
            await client.wait_for(lambda m: m.revision == 1, WAIT)
            labels = [s.label for s in client.mission.tasks["lru1"]]
            assert labels.count("full") == 1
            now = server.mission.model_dump_json()
        assert await restarted(db) == now

    asyncio.run(asyncio.wait_for(scenario(), 90))


def test_a_journal_locked_by_another_program_refuses_within_the_client_timeout(tmp_path):
    """A real SQLite lock (say, the sqlite3 shell in a write transaction):
    the server waits briefly for it, then refuses; the client hears the
    refusal, not its own timeout."""
    db = tmp_path / "m.db"

    async def scenario():
        async with serving(db) as (_server, client):
            other = sqlite3.connect(db, isolation_level=None)
            try:
                other.execute("BEGIN EXCLUSIVE")
                with pytest.raises(OperationRefused) as refused:
                    await client.submit(drive_to("locked"), timeout=8)
                assert refused.value.code == "journal_failed"
                assert "locked" in str(
                    refused.value
                ) and "another program holds the file locked" in str(refused.value)
                other.execute("ROLLBACK")
                reply = await client.submit(drive_to("locked"))
                assert reply.revision == 1
            finally:
                other.close()

    asyncio.run(asyncio.wait_for(scenario(), 60))


def test_an_undo_the_journal_cannot_take_can_be_sent_again(tmp_path):
    async def scenario():
        async with serving(tmp_path / "m.db") as (server, client):
            await client.submit(drive_to("undo me"))
            real = server.journal._conn
            server.journal._conn = FullDisk(real)
            with pytest.raises(OperationRefused, match="the mission was not changed"):
                await client.submit(Undo())
            server.journal._conn = real
            reply = await client.submit(Undo())  # still in the history
            assert reply.revision == 2
            assert "undo me" not in [s.label for s in server.mission.tasks["lru1"]]

    asyncio.run(asyncio.wait_for(scenario(), 60))


def test_a_robot_report_the_journal_cannot_take_is_kept_by_the_robot(tmp_path):
    db = tmp_path / "m.db"

    async def handler(ctx, **params):
        ctx.progress(1.0)

    async def scenario():
        async with serving(db) as (server, client):
            agent = RobotAgent(
                "lru1",
                "lru_science",
                connect=server.listen,
                modules={"base": "1.0.0"},
                lease_ms=1000,
            )
            agent.add_skill("drive_to", handler, version="1.0.0", raw=True)
            try:
                await agent.start()
                await agent.wait_registered(timeout=WAIT)
                await client.submit(Sync(robot="lru1", through="lru1-1"))
                real = server.journal._conn
                full = server.journal._conn = FullDisk(real)
                await client.submit(Control(op="run", robot="lru1"))  # journals nothing
                assert await asyncio.to_thread(full.tried.wait, WAIT), (
                    "the robot's report never reached the journal"
                )
                assert status(server.mission, "lru1-1") == "idle_synchronized"
                server.journal._conn = real
                await client.wait_for(lambda m: status(m, "lru1-1") == "success", WAIT)
                assert full.refused >= 1
                now = server.mission.model_dump_json()
            finally:
                await agent.stop()
        assert await restarted(db) == now

    asyncio.run(asyncio.wait_for(scenario(), 90))


def test_a_deleted_journal_is_noticed_before_writing_into_it(tmp_path):
    db = tmp_path / "m.db"

    async def scenario():
        async with serving(db) as (server, client):
            for f in tmp_path.glob("m.db*"):
                f.unlink()
            with pytest.raises(OperationRefused) as refused:
                await client.submit(drive_to())
            assert refused.value.code == "journal_failed"
            assert "deleted or replaced" in str(refused.value) and "missionctl ctl save" in str(
                refused.value
            )
            assert server.mission.revision == 0

    asyncio.run(asyncio.wait_for(scenario(), 60))


def test_a_second_server_on_the_same_journal_is_refused(tmp_path):
    db = tmp_path / "m.db"
    with Journal.open(db):  # a running server holds it open
        with pytest.raises(JournalError, match="in use by another process"):
            Journal.open(db)
        second = subprocess.run(
            [
                sys.executable,
                "-m",
                "backend.cli",
                "server",
                "--mission",
                str(TUTORIAL),
                "--db",
                str(db),
                "--listen",
                loopback_endpoint(free_port()),
            ],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=60,
        )
    assert second.returncode == 2, second.stderr
    assert f"{db} is in use by another process" in second.stderr
    assert "Traceback" not in second.stderr


def test_a_restart_on_a_journal_says_the_mission_file_was_not_read(tmp_path):
    db = tmp_path / "m.db"
    other = ROOT / "missions" / "mars_sample_return.yaml"
    for mission, expect in ((TUTORIAL, "started from"), (other, f"{other} was not read")):
        server = Proc(
            [
                sys.executable,
                "-m",
                "backend.cli",
                "server",
                "--mission",
                str(mission),
                "--db",
                str(db),
                "--listen",
                loopback_endpoint(free_port()),
            ]
        )
        try:
            server.wait_line(expect)
            assert "mission 'Tutorial'" in server.output()
        finally:
            server.stop()


def test_a_robot_operation_retried_after_a_server_restart_is_applied_once(tmp_path):
    """The request id of sync/unsync/retry is journaled with the robot's
    acknowledgement: a client whose reply was lost in the restart retries
    and is told it was applied (not refused, not applied again)."""
    db = tmp_path / "m.db"

    async def scenario():
        endpoint = loopback_endpoint(free_port())
        server = new_server(db, endpoint)
        await server.start()
        agent = RobotAgent(
            "lru1", "lru_science", connect=[endpoint], modules={"base": "1.0.0"}, lease_ms=1000
        )

        async def handler(ctx, **params):
            ctx.progress(1.0)

        for skill in ("drive_to", "take_science_image"):
            agent.add_skill(skill, handler, version="1.0.0", raw=True)
        try:
            async with MissionClient(endpoint, client_id="t") as client:
                await agent.start()
                await agent.wait_registered(timeout=WAIT)
                synced = await client.submit(Sync(robot="lru1"), request_id="s1")
                unsynced = await client.submit(
                    Unsync(robot="lru1", from_id="lru1-2"), request_id="u1"
                )
        finally:
            await agent.stop()
            await server.stop()
        endpoint = loopback_endpoint(free_port())
        server = new_server(db, endpoint)
        await server.start()
        try:
            async with MissionClient(endpoint, client_id="t") as client:
                for op, rid, first in (
                    (Sync(robot="lru1"), "s1", synced),
                    (Unsync(robot="lru1", from_id="lru1-2"), "u1", unsynced),
                ):
                    again = await client.submit(op, request_id=rid)
                    assert again.duplicate and again.revision == first.revision, (rid, again)
                assert status(client.mission, "lru1-1") == "idle_synchronized"
                assert status(client.mission, "lru1-2") == "idle"
        finally:
            await server.stop()

    asyncio.run(asyncio.wait_for(scenario(), 90))


def test_an_operation_nobody_answers_may_have_been_applied(tmp_path):
    """The server goes away while a request is out: the error says it may
    have been applied and carries the request id to retry with."""

    async def scenario():
        async with serving(tmp_path / "m.db") as (server, client):
            for (
                q
            ) in server._entities:  # the operations queryable goes: as in a crash, no reply at all
                if hasattr(q, "undeclare"):
                    q.undeclare()
            with pytest.raises(ServerGone) as gone:
                await client.submit(drive_to(), request_id="lost-1")
            assert isinstance(gone.value, ServerUnreachable)
            assert gone.value.request_id == "lost-1"
            assert "may have applied it" in str(gone.value) and "request id lost-1" in str(
                gone.value
            )

    asyncio.run(asyncio.wait_for(scenario(), 60))


def test_a_journal_that_cannot_take_its_first_snapshot_is_a_clear_error(tmp_path, monkeypatch):
    def full(self, mission):
        raise sqlite3.OperationalError("database or disk is full")

    monkeypatch.setattr(Journal, "snapshot", full)
    server = new_server(tmp_path / "m.db", loopback_endpoint(free_port()))
    with pytest.raises(
        JournalError, match="cannot write the journal's first snapshot: database or disk is full"
    ):
        server._load()
    assert server.journal is None
    Journal.open(tmp_path / "m.db").close()  # closed again: not held "in use"
