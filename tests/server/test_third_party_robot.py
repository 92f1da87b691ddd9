"""docs/protocol.md promises that a third party can connect a robot to a
mission server "without reading our code". `ThirdPartyRobot` below is such a
robot: written from that document alone, with the `zenoh` package, `json` and
the standard library (no missionctl model or SDK), key expressions and field
names spelled as the document spells them. The operator side of the tests is
ours (MissionClient against a real server subprocess, tests/server/harness.py).
"""

from __future__ import annotations

import asyncio
import json
import threading
from datetime import UTC, datetime

import pytest
import zenoh

from backend.client.client import OperationRefused
from backend.core.ops import Control, Sync
from backend.transport.session import close_session

from .harness import drive, status

pytestmark = pytest.mark.timeout(120)

# missions/libraries/mars.yaml: the skills of type lru_science, all at library
# version 1.0.0 (the default). Minor versions may differ: only majors must match.
LRU_SCIENCE = {
    "drive_to": "1.4.2",
    "explore": "1.0.0",
    "take_science_image": "1.0.0",
    "identify_stone": "1.1.0",
    "recharge": "1.0.0",
}


class ThirdPartyRobot:
    """A robot whose skills succeed at once. Zenoh callbacks only record and
    answer; every query (register, reports) is made by one worker thread."""

    def __init__(
        self, endpoint: str, name: str, rtype: str, skills: dict[str, str], *, protocol: int = 1
    ):
        self.name = name
        self.manifest = {
            "name": name,
            "type": rtype,
            "protocol": protocol,
            "modules": [{"name": "base", "version": "1.0.0"}],
            "skills": skills,
        }
        self.queue: list[str] = []  # synchronized, not started (ids)
        self.done: set[str] = set()
        self.enqueued: list[dict] = []  # every SkillInstance received
        self.outbox: list[dict] = []  # reports not acknowledged yet
        self.seq = 0
        self.run_mode = False
        self.server_up = False
        self.must_register = False
        self.registered = False  # accepted
        self.register_reply: dict | None = None
        self.refused: list[dict] = []  # ErrorReplies of refused reports (ReportAck.refused)
        self.lock = (
            threading.Condition()
        )  # guards the above; notified on every reply from the server
        self.wake = threading.Event()
        self.closing = False
        # "The mission server is the Zenoh router ...; robots connect in client mode", scouting off
        config = zenoh.Config()
        config.insert_json5("mode", '"client"')
        config.insert_json5("connect/endpoints", json.dumps([endpoint]))
        config.insert_json5("scouting/multicast/enabled", "false")
        self.session = zenoh.open(config)
        try:
            # Robot registration step 1: queryables (command, world), the
            # liveliness token, then watch the server's token (history: it may be there already)
            prefix = f"mc/v1/robot/{name}"
            self.entities = [  # kept: a dropped liveliness token is undeclared
                self.session.declare_queryable(f"{prefix}/cmd", self._on_command),
                self.session.declare_queryable(f"{prefix}/world", self._on_world),
                self.session.liveliness().declare_token(f"{prefix}/alive"),
                self.session.liveliness().declare_subscriber(
                    "mc/v1/server/alive", self._on_server, history=True
                ),
            ]
            self.worker = threading.Thread(target=self._work, name=f"robot-{name}", daemon=True)
            self.worker.start()
        except BaseException:
            self.session.close()
            raise

    # -- Zenoh callbacks: never block, never query from here (FIELD-NOTES; Reports:
    #    "answer a command before waiting for anything from the server")
    def _on_server(self, sample: zenoh.Sample) -> None:
        with self.lock:  # registration step 2: register whenever the server token appears
            self.server_up = self.must_register = sample.kind == zenoh.SampleKind.PUT
            self.registered = False
        self.wake.set()

    def _on_command(self, query: zenoh.Query) -> None:
        # Key space: Command -> CommandReply (or reply_err with an ErrorReply)
        with query:  # finalised on exit, else the server waits for more replies
            cmd = json.loads(query.payload.to_bytes()) if query.payload is not None else {}
            with self.lock:
                reply = self._command(cmd)
                if reply is None:
                    error = {
                        "code": "bad_request",
                        "message": f"{self.name} does not know command {cmd.get('cmd')!r}",
                        "robot": self.name,
                    }
                    query.reply_err(json.dumps(error))
                    return
                reply["reports"] = list(
                    self.outbox
                )  # unacknowledged changes ride along (Unsynchronize, 3.)
            query.reply(query.key_expr, json.dumps(reply))
        self.wake.set()

    def _command(self, cmd: dict) -> dict | None:
        kind = cmd.get("cmd")
        if (
            kind == "enqueue"
        ):  # Synchronize, 3. and 5.: append (or put in front) what is new, answer the ids
            ids = [s["id"] for s in cmd["skills"] if s["id"] not in self.done]
            new = [i for i in ids if i not in self.queue]
            self.enqueued += cmd["skills"]
            self.queue = new + self.queue if cmd.get("front") else self.queue + new
            return {"ids": ids}
        if kind == "dequeue":  # Unsynchronize, 3.: remove what has not started, name the rest
            kept = [i for i in cmd["ids"] if i in self.done]
            self.queue = [i for i in self.queue if i not in cmd["ids"]]
            return {"ids": [i for i in cmd["ids"] if i not in kept], "kept": kept}
        if kind in (
            "run",
            "pause",
            "stop",
        ):  # Run, pause, stop, reset (skills here are instantaneous)
            self.run_mode = kind == "run"
            return {}
        if kind == "reset":
            removed, self.queue, self.run_mode = self.queue, [], False
            return {"ids": removed}
        return None

    def _on_world(self, query: zenoh.Query) -> None:
        with query:  # World knowledge: this robot knows nothing
            query.reply(query.key_expr, json.dumps({"known": False, "data": {}}))

    # -- the worker thread: registration, execution, report delivery
    def _work(self) -> None:
        while not self.closing:
            self.wake.wait(0.5)  # woken by callbacks; the timeout retries failed deliveries
            self.wake.clear()
            if self.closing:
                return
            with self.lock:
                register = self.must_register
            if register:
                self._register()
            with self.lock:
                if self.registered and self.run_mode and self.queue:
                    sid = self.queue.pop(0)  # Run: execute the head of the queue ...
                    self._report(sid, "running")
                    self._report(sid, "success")  # ... which succeeds at once
                    self.done.add(sid)
                    self.wake.set()  # then the next one
                flush = self.registered and bool(self.outbox)
            if flush:
                self._flush()

    def _register(self) -> None:
        # Robot registration 2.-3.: Register{manifest, queue, reports}; number after last_seq
        with self.lock:
            self.must_register = False  # set again if the server token reappears meanwhile
            request = {
                "manifest": self.manifest,
                "queue": [{"id": i, "status": "idle_synchronized"} for i in self.queue],
                "reports": list(self.outbox),
            }
        reply = self._ask(f"mc/v1/server/register/{self.name}", request)
        with self.lock:
            if reply is None:  # unanswered: again while the server is up
                self.must_register = self.must_register or self.server_up
                return
            self.register_reply = (
                reply  # registration 4.: not accepted -> wait for the token to reappear
            )
            if reply.get("accepted", True):
                self._acknowledged(reply.get("last_seq", 0))
                self.registered = True
            self.lock.notify_all()

    def _report(self, sid: str, status: str) -> None:
        # Reports: one Report per status change, `seq` + 1 per robot, kept in the outbox
        self.seq += 1
        self.outbox.append(
            {
                "robot": self.name,
                "seq": self.seq,
                "id": sid,
                "status": status,
                "info": "",
                "at": datetime.now(UTC).isoformat(),
            }
        )

    def _flush(self) -> None:
        with self.lock:
            batch = {"reports": list(self.outbox)}
        ack = self._ask(f"mc/v1/server/report/{self.name}", batch)  # ReportBatch -> ReportAck
        if ack is not None:
            with self.lock:
                self._acknowledged(ack["last_seq"])  # refused reports are acknowledged too
                self.refused += ack.get("refused", [])
                self.lock.notify_all()

    def _acknowledged(self, last_seq: int) -> None:
        self.outbox = [r for r in self.outbox if r["seq"] > last_seq]
        self.seq = max(self.seq, last_seq)  # "the robot continues numbering after it"

    def _ask(self, key: str, message: dict) -> dict | None:
        """One query, its OK reply as a dict; None when refused or unanswered (retried later)."""
        for reply in self.session.get(key, payload=json.dumps(message), timeout=5.0):
            if reply.ok is not None:
                return json.loads(reply.ok.payload.to_bytes())
        return None

    def wait_until(self, predicate, timeout: float = 10.0) -> bool:
        with self.lock:
            return self.lock.wait_for(predicate, timeout)

    def close(self) -> None:
        self.closing = True
        self.wake.set()
        try:
            self.worker.join(10)
        finally:
            self.session.close()  # explicitly: an open session hangs the interpreter at exit


@pytest.fixture
def robots(cluster):
    made: list[ThirdPartyRobot] = []

    def make(
        name: str = "lru1", rtype: str = "lru_science", skills: dict[str, str] = LRU_SCIENCE, **kw
    ) -> ThirdPartyRobot:
        made.append(ThirdPartyRobot(cluster.endpoint, name, rtype, skills, **kw))
        return made[-1]

    yield make
    for robot in made:
        try:
            robot.close()
        finally:
            # whatever close() did: backend's close_session is idempotent and
            # makes sure no session stays open (the exit hang of FIELD-NOTES)
            close_session(robot.session)


async def until(robot: ThirdPartyRobot, predicate, what: str) -> None:
    assert await asyncio.to_thread(robot.wait_until, predicate), f"{robot.name}: {what} within 10 s"


async def online(c) -> None:
    await c.wait_for(lambda _m: "lru1" in c.robots and c.robots["lru1"].online, 10)  # FleetEvent


async def registered(robot: ThirdPartyRobot) -> dict:
    await until(robot, lambda: robot.register_reply is not None, "no RegisterReply")
    return robot.register_reply


def test_a_robot_built_from_the_doc_registers_syncs_and_runs(cluster, robots):
    robot = robots()

    async def scenario(c):
        reply = await registered(robot)
        assert reply["accepted"] is True and reply["last_seq"] == 0
        await online(c)
        assert c.robots["lru1"].manifest.skills == LRU_SCIENCE  # FleetEvent carries the manifest

        # Synchronize: drive_to 1.4.2 serves the library's 1.0.0 (same major)
        done = await c.submit(Sync(robot="lru1", through="lru1-1"))
        assert done.value["synchronized"] == ["lru1-1"]
        m = await c.wait_for(lambda m: status(m, "lru1-1") == "idle_synchronized", 10)
        assert status(m, "lru1-2") == "idle"
        assert robot.queue == ["lru1-1"]
        [sent] = robot.enqueued
        assert sent["id"] == "lru1-1" and sent["skill"] == "drive_to"

        # Run: the robot reports running then success; the server acknowledges both
        await c.submit(Control(op="run", robot="lru1"))
        m = await c.wait_for(lambda m: status(m, "lru1-1") == "success", 10)
        skill = m.find("lru1-1")[2]
        assert skill.started_at is not None and skill.finished_at is not None  # from Report.at
        assert status(m, "lru1-2") == "idle"  # never synchronized: never run
        # both reports acknowledged (ReportAck.last_seq) and dropped, none refused
        await until(robot, lambda: robot.outbox == [], "reports still unacknowledged")
        assert robot.seq == 2 and robot.refused == []
        assert robot.queue == [] and robot.done == {"lru1-1"}

    drive(cluster, scenario)


def test_sync_is_refused_as_incompatible_when_the_manifest_lacks_a_skill(cluster, robots):
    robot = robots(skills={k: v for k, v in LRU_SCIENCE.items() if k != "take_science_image"})

    async def scenario(c):
        assert (await registered(robot))["accepted"] is True
        await online(c)
        with pytest.raises(OperationRefused) as refused:
            await c.submit(Sync(robot="lru1"))  # lru1-1 drive_to, lru1-2 take_science_image
        err = refused.value.reply  # the ErrorReply: stable code, a sentence naming robot and skill
        assert err.code == "incompatible" and err.robot == "lru1" and err.skill == "lru1-2"
        assert "take_science_image" in err.message
        m = await c.resync()
        assert [status(m.mission, s) for s in ("lru1-1", "lru1-2")] == [
            "idle",
            "idle",
        ]  # nothing changed
        assert robot.enqueued == []  # and nothing was sent to the robot

    drive(cluster, scenario)


def test_a_robot_speaking_another_protocol_version_is_not_accepted(cluster, robots):
    robot = robots(protocol=2)

    async def scenario(c):
        reply = await registered(robot)
        assert reply["accepted"] is False and "protocol" in reply["reason"]
        snap = await c.resync()
        assert not snap.robots[
            "lru1"
        ].online  # its token alone does not make it online (registration, 4.)
        with pytest.raises(OperationRefused) as refused:
            await c.submit(Sync(robot="lru1"))
        assert refused.value.code == "robot_offline"

    drive(cluster, scenario)


def test_a_restarted_robot_is_told_which_skills_it_lost(cluster, robots):
    first = robots()

    async def scenario(c):
        assert (await registered(first))["accepted"] is True
        await online(c)
        await c.submit(Sync(robot="lru1", through="lru1-1"))
        await c.wait_for(lambda m: status(m, "lru1-1") == "idle_synchronized", 10)
        first.close()  # the robot restarts: its queue is gone
        await c.wait_for(lambda _m: not c.robots["lru1"].online, 10)
        again = robots()
        reply = await registered(again)
        # registration 3.: what the server held for it goes back to the plan, and the robot is told
        assert reply["accepted"] is True and reply["missing"] == ["lru1-1"]
        await c.wait_for(lambda m: status(m, "lru1-1") == "idle", 10)

    drive(cluster, scenario)


def test_a_robot_registering_under_another_name_is_refused(cluster, robots):
    robot = robots()  # lru1, registered as itself; its session now asks as another robot
    manifest = {**robot.manifest, "name": "lru2"}  # on lru1's key (registration, 4.)
    reply = [
        r
        for r in robot.session.get(
            "mc/v1/server/register/lru1",
            timeout=5.0,
            payload=json.dumps({"manifest": manifest, "queue": [], "reports": []}),
        )
    ]
    [err] = [r.err for r in reply if r.err is not None]
    refusal = json.loads(err.payload.to_bytes())  # an ErrorReply
    assert (
        refusal["code"] == "bad_register"
        and "lru2" in refusal["message"]
        and "lru1" in refusal["message"]
    )
