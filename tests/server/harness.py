"""Multi-process fixtures: a mission server and robot agents in subprocesses,
clients in the test process; free loopback ports; everything stopped in
teardown. Also a server in the test process (`serving`), for tests that
reach into it."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import threading
from contextlib import asynccontextmanager
from datetime import UTC, datetime
from pathlib import Path

from backend.client.client import MissionClient
from backend.core.model import Status
from backend.core.ops import Answer, Report
from backend.files.missions import load_mission
from backend.protocol.keys import Keys
from backend.protocol.messages import (
    Downlink,
    DownlinkAck,
    Manifest,
    Module,
    QueueEntry,
    Register,
    RegisterReply,
    Uplink,
    UplinkEntry,
    UplinkReceipt,
    WorldMessage,
    dumps,
)
from backend.server.server import MissionServer
from backend.transport import (
    client_config,
    declare_token,
    free_port,
    loopback_endpoint,
    query,
    serve_async,
)
from backend.transport.session import close_session, open_session

ROOT = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
TUTORIAL = ROOT / "missions" / "tutorial.yaml"


def new_server(db, endpoint: str, **kw) -> MissionServer:
    """A server in the test process on the tutorial mission."""
    return MissionServer(db=db, mission_file=TUTORIAL, listen=[endpoint], **kw)


@asynccontextmanager
async def serving(db, **kw):
    """A server in the test process on `db` (free loopback port; `kw`: its
    options) and a client connected to it, both closed afterwards."""
    endpoint = loopback_endpoint(free_port())
    server = new_server(db, endpoint, **kw)
    await server.start()
    client = MissionClient(endpoint, client_id="t")
    try:
        await client.connect()
        yield server, client
    finally:
        await client.close()
        await server.stop()


class Proc:
    """A subprocess whose output lines can be awaited (a reader thread takes
    them off the pipe: select() on a buffered pipe misses lines already read)."""

    def __init__(self, args: list[str]):
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        self.p = subprocess.Popen(
            args, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        self.lines: list[str] = []
        self._cond = threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.p.stdout:
            with self._cond:
                self.lines.append(line)
                self._cond.notify_all()
        with self._cond:
            self._cond.notify_all()

    def output(self) -> str:
        with self._cond:
            return "".join(self.lines)

    def wait_line(self, needle: str, timeout: float = 20.0) -> str:
        def found() -> str | None:
            return next((line for line in self.lines if needle in line), None)

        with self._cond:
            if (
                self._cond.wait_for(
                    lambda: found() is not None or self.p.poll() is not None, timeout
                )
                and found()
            ):
                return found()
        raise AssertionError(
            f"no {needle!r} from {self.p.args} within {timeout}s; output:\n{self.output()}"
        )

    def kill(self, sig: int = signal.SIGKILL) -> None:
        if self.p.poll() is None:
            self.p.send_signal(sig)
        try:
            self.p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.p.kill()
            self.p.wait()

    def stop(self) -> None:
        self.kill(signal.SIGTERM)


class Cluster:
    def __init__(self, tmp: Path, mission: str):
        self.port = free_port()
        self.endpoint = loopback_endpoint(self.port)
        self.db = tmp / "mission.db"
        self.mission = str(ROOT / mission)
        self.procs: list[Proc] = []
        self.server: Proc | None = None

    def start_server(self) -> Proc:
        self.server = Proc(
            [
                sys.executable,
                "-m",
                "backend.cli",
                "server",
                "--mission",
                self.mission,
                "--listen",
                self.endpoint,
                "--db",
                str(self.db),
                "-v",
            ]
        )
        self.procs.append(self.server)
        self.server.wait_line("listening on")
        return self.server

    def start_robots(self, *robots: str, delay: float = 0.0) -> Proc:
        p = Proc(
            [
                sys.executable,
                str(ROOT / "docs" / "examples" / "trivial_robots.py"),
                "--connect",
                self.endpoint,
                "--delay",
                str(delay),
                "-v",
                *robots,
            ]
        )
        self.procs.append(p)  # before waiting: stopped in teardown even if never ready
        for r in robots:
            p.wait_line(f"ready {r.split(':')[0]}")
        return p

    def stop(self) -> None:
        for p in reversed(self.procs):
            p.stop()


class RawRobot:
    """A robot on a plain Zenoh session, without the SDK (protocol 2 models):
    its presence token, an uplink queryable that processes each command once
    in seq order (`answer` says what it did: by default everything asked),
    `report()` for status changes, and a downlink it sends after each
    command (`flush`). Declared by `register` (on the running loop)."""

    def __init__(self, endpoint: str, name: str, session: str = "raw1"):
        self.name = name
        self.rtype = ""
        self.session_id = session
        self.session = open_session(client_config([endpoint]))
        self.received: list[UplinkEntry] = []  # every command processed, in order
        self.transmissions = 0  # Uplink queries received
        self.applied = 0  # last uplink seq processed
        self.seq = 0  # last downlink seq made
        self.outbox: list[Report | Answer] = []
        self.acks: list[DownlinkAck] = []
        self.hold = False  # True: answers wait in the outbox (flush() sends them)
        self._entities: list = []
        self._tasks: set[asyncio.Task] = set()

    def _on_uplink(self, payload: bytes) -> bytes:
        up = Uplink.model_validate_json(payload)
        self.transmissions += 1
        for e in sorted(up.commands, key=lambda e: e.seq):
            if e.seq <= self.applied:
                continue
            self.applied = e.seq
            self.received.append(e)
            self.seq += 1
            self.outbox.append(self.answer(e, self.seq))
        if not self.hold and self.outbox:
            task = asyncio.get_running_loop().create_task(self.flush())
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)
        return dumps(UplinkReceipt(session=self.session_id, applied=self.applied))

    def answer(self, e: UplinkEntry, seq: int) -> Answer:
        cmd = e.command
        ids = [s.id for s in cmd.skills] if cmd.cmd == "enqueue" else []
        removed = list(cmd.ids) if cmd.cmd == "dequeue" else []
        return Answer(
            robot=self.name, seq=seq, command=e.seq, outcome="applied", queued=ids, removed=removed
        )

    def report(self, skill_id: str, status: Status) -> Report:
        self.seq += 1
        r = Report(robot=self.name, seq=self.seq, id=skill_id, status=status, at=datetime.now(UTC))
        self.outbox.append(r)
        return r

    def downlink(self, messages: list) -> Downlink:
        return Downlink(
            robot=self.name,
            session=self.session_id,
            messages=list(messages),
            uplink_applied=self.applied,
            sent=datetime.now(UTC),
        )

    async def flush(self, messages: list | None = None) -> DownlinkAck:
        """Send the outbox (or `messages`) as one Downlink; drop what is acknowledged."""
        dl = self.downlink(self.outbox if messages is None else messages)
        ack = DownlinkAck.model_validate_json(
            await query(self.session, Keys.downlink(self.name), dumps(dl), 10.0)
        )
        self.acks.append(ack)
        self.outbox = [m for m in self.outbox if m.seq > ack.last_seq]
        return ack

    def registration(self, queue: list[str] = (), sent: datetime | None = None) -> Register:
        _, library = load_mission(ROOT / "missions" / "tutorial.yaml")
        manifest = Manifest(
            name=self.name,
            type=self.rtype,
            modules=[Module(name="base", version="1.0.0")],
            skills={s: library.skills[s].version for s in library.skills_of(self.rtype)},
        )
        return Register(
            manifest=manifest,
            session=self.session_id,
            downlink=list(self.outbox),
            last_seq=self.seq,
            uplink_applied=self.applied,
            queue=[QueueEntry(id=i, status=Status.IDLE_SYNCHRONIZED) for i in queue],
            sent=sent,
        )

    async def register(
        self, rtype: str, queue: list[str] = (), sent: datetime | None = None
    ) -> RegisterReply:
        """Register (`sent`: when it says the registration left it)."""
        self.rtype = rtype
        if not self._entities:
            self._entities = [
                declare_token(self.session, Keys.alive(self.name, self.session_id)),
                serve_async(self.session, Keys.uplink(self.name), self._on_uplink),
            ]
        reply = RegisterReply.model_validate_json(
            await query(
                self.session, Keys.register(self.name), dumps(self.registration(queue, sent)), 10.0
            )
        )
        assert reply.accepted, reply.reason
        self.outbox = [m for m in self.outbox if m.seq > reply.last_seq]
        return reply

    def close(self) -> None:
        for t in self._tasks:
            t.cancel()
        self._entities.clear()
        close_session(self.session)


def drive(cluster: Cluster, scenario, *, clients: int = 1, timeout: float = 90.0):
    """Run `scenario(*clients)` on a fresh event loop with connected clients
    (closed afterwards, whatever happens)."""

    async def main():
        opened = []
        try:
            for i in range(clients):
                c = MissionClient(cluster.endpoint, client_id=f"test{i}")
                await c.connect()
                opened.append(c)
            return await asyncio.wait_for(scenario(*opened), timeout)
        finally:
            for c in opened:
                await c.close()

    return asyncio.run(main())


async def tell(client: MissionClient, robot: str, topic: str, data: dict) -> None:
    msg = WorldMessage(kind="tell", sender="test", topic=topic, data=data)
    await query(client.session, Keys.world(robot), dumps(msg), 5.0)


def status(mission, sid: str) -> str | None:
    found = mission.find(sid)
    return found[2].status.value if found else None


async def until(client: MissionClient, pred, timeout: float = 15.0):
    return await client.wait_for(pred, timeout)


__all__ = ["Cluster", "Proc", "RawRobot", "drive", "status", "tell", "until"]
