"""A robot in run mode starts a skill as soon as it is enqueued and may report
it before its reply to the enqueue reaches the server. The server must apply
that report after the synchronization, not refuse it (the skill would stay
queued on the ground while it ran on the robot)."""

from __future__ import annotations

import json
from datetime import UTC, datetime

import zenoh
from zenoh.handlers import Callback

from backend.files import load_mission
from backend.model import Status
from backend.ops import Report, Sync
from backend.protocol import (
    CommandReply,
    Keys,
    Manifest,
    Module,
    QueueEntry,
    Register,
    RegisterReply,
    ReportBatch,
    dumps,
)
from backend.transport import client_config, declare_token, query, serve
from backend.transport.session import close_session, open_session

from .harness import ROOT, drive, status


class EagerRobot:
    """Answers an enqueue only after sending `running` for its first skill,
    like an agent whose handler started before the reply left. With
    `via_register`, the report rides on a new registration instead (a robot
    whose link dropped and came back while the enqueue was in flight)."""

    def __init__(self, endpoint: str, name: str, *, via_register: bool = False):
        self.name = name
        self.seq = 0
        self.via_register = via_register
        self.rtype = ""
        self.session = open_session(client_config([endpoint]))
        self._entities = [declare_token(self.session, Keys.alive(name)),
                          serve(self.session, Keys.command(name), self._on_command)]

    def _on_command(self, payload: bytes) -> bytes:
        cmd = json.loads(payload)
        ids = [s["id"] for s in cmd.get("skills", [])] if cmd.get("cmd") == "enqueue" else []
        if ids:
            self.seq += 1
            report = Report(robot=self.name, seq=self.seq, id=ids[0], status=Status.RUNNING, at=datetime.now(UTC))
            if self.via_register:
                key, payload = Keys.register(self.name), dumps(self._register(reports=[report], queue=ids))
            else:
                key, payload = Keys.reports(self.name), dumps(ReportBatch(reports=[report]))
            # sent (not awaited) before this reply: it reaches the server first
            self.session.get(key, Callback(lambda _reply: None, lambda: None, indirect=False),
                             payload=payload, timeout=10.0, consolidation=zenoh.ConsolidationMode.NONE)
        return dumps(CommandReply(ids=ids))

    def _register(self, reports: list[Report] = (), queue: list[str] = ()) -> Register:
        _, library = load_mission(ROOT / "missions" / "tutorial.yaml")
        manifest = Manifest(name=self.name, type=self.rtype, modules=[Module(name="base", version="1.0.0")],
                            skills={s: library.skills[s].version for s in library.skills_of(self.rtype)})
        return Register(manifest=manifest, reports=list(reports), queue=[QueueEntry(id=i, status=Status.RUNNING) for i in queue])

    async def register(self, rtype: str) -> None:
        self.rtype = rtype
        reply = RegisterReply.model_validate_json(
            await query(self.session, Keys.register(self.name), dumps(self._register()), 10.0))
        assert reply.accepted, reply.reason

    def close(self) -> None:
        self._entities.clear()
        close_session(self.session)


def test_a_report_sent_before_the_enqueue_reply_is_applied_after_the_sync(cluster):
    robot = EagerRobot(cluster.endpoint, "lru1")
    try:
        async def scenario(c):
            await robot.register("lru_science")  # online once registered
            reply = await c.submit(Sync(robot="lru1", through="lru1-1"))
            assert reply.value["synchronized"] == ["lru1-1"]
            m = await c.wait_for(lambda m: status(m, "lru1-1") == "running", 10)
            assert m.report_seqs["lru1"] == 1  # applied, not refused and consumed

        drive(cluster, scenario)
    finally:
        robot.close()


def test_a_registration_during_the_enqueue_waits_for_it(cluster):
    robot = EagerRobot(cluster.endpoint, "lru1", via_register=True)
    try:
        async def scenario(c):
            await robot.register("lru_science")
            reply = await c.submit(Sync(robot="lru1", through="lru1-1"))
            assert reply.value["synchronized"] == ["lru1-1"]
            m = await c.wait_for(lambda m: status(m, "lru1-1") == "running", 10)
            assert m.report_seqs["lru1"] == 1

        drive(cluster, scenario)
    finally:
        robot.close()
