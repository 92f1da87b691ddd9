"""docs/protocol.md promises that a third party can connect a robot to a
mission server "without reading our code". `WireRobot` below is such a robot:
written from that document alone, with the `zenoh` package, `json` and the
standard library (no missionctl model or SDK), key expressions and field
names spelled as the document spells them. It can also misbehave on purpose
(answer with part of the ids, skip a number, send messages twice, register
twice, send garbage): the ground must never show a skill the robot does not
hold, never drop a report, and name the robot, not the operator, in errors.
The operator side is ours (MissionClient against a real server subprocess).
"""

from __future__ import annotations

import asyncio
import json
import secrets
import threading
from datetime import UTC, datetime
from pathlib import Path

import pytest
import zenoh

from backend.client.client import OperationRefused
from backend.client.events import AlertRaised
from backend.core.ops import Control, Sync, Unsync
from backend.transport.session import close_session

from .harness import ROOT, Cluster, drive, status

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
V = "mc/v2"  # "Key space"


def _now() -> str:
    return datetime.now(UTC).isoformat()


class WireRobot:
    """A robot whose skills succeed at once. Zenoh callbacks only record and
    answer ("never query the server from inside a query callback"); every
    query (register, downlink) is made by one worker thread."""

    def __init__(self, endpoint: str, name: str, skills: dict[str, str], *, protocol: int = 2):
        self.name = name
        self.session_id = secrets.token_hex(6)  # "fresh at every start"
        self.manifest = {
            "name": name,
            "type": "lru_science",
            "protocol": protocol,
            "modules": [{"name": "base", "version": "1.0.0"}],
            "skills": skills,
        }
        self.queue: list[str] = []  # held, not started (ids)
        self.done: list[str] = []
        self.enqueued: list[dict] = []  # every skill received
        self.outbox: list[dict] = []  # downlink messages not acknowledged yet
        self.seq = 0  # last downlink seq made
        self.applied = 0  # last uplink seq processed
        self.run_mode = False
        self.must_register = False
        self.registered = False
        self.register_reply: dict | None = None
        self.acks: list[dict] = []
        self.errors: list[dict] = []  # ErrorReplies the server answered with
        self.refused: list[dict] = []  # DownlinkAck.refused
        # misbehaviour, set by a test
        self.partial = False  # enqueue: hold only the first skill sent
        self.lock = threading.Condition()
        self.wake = threading.Event()
        self.closing = False
        config = zenoh.Config()  # "Zenoh settings of a client"
        config.insert_json5("mode", '"client"')
        config.insert_json5("connect/endpoints", json.dumps([endpoint]))
        config.insert_json5("listen/endpoints", "[]")
        config.insert_json5("scouting/multicast/enabled", "false")
        config.insert_json5("scouting/gossip/enabled", "false")
        config.insert_json5("transport/link/tx/lease", "1000")
        self.session = zenoh.open(config)
        try:
            # "Registration and reconciliation", 1.: queryables, token, watch the server
            self.entities = [
                self.session.declare_queryable(f"{V}/robot/{name}/uplink", self._on_uplink),
                self.session.declare_queryable(f"{V}/robot/{name}/world", self._on_world),
                self.session.liveliness().declare_token(
                    f"{V}/robot/{name}/alive/{self.session_id}"
                ),
                self.session.liveliness().declare_subscriber(
                    f"{V}/server/alive", self._on_server, history=True
                ),
            ]
            self.worker = threading.Thread(target=self._work, name=f"robot-{name}", daemon=True)
            self.worker.start()
        except BaseException:
            self.session.close()
            raise

    # -- callbacks ------------------------------------------------------------------
    def _on_server(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.must_register = sample.kind == zenoh.SampleKind.PUT
            self.registered = False
        self.wake.set()

    def _on_uplink(self, query: zenoh.Query) -> None:
        """ "The uplink": a receipt at once; each command processed once, in seq order."""
        with query:
            up = json.loads(query.payload.to_bytes())
            if up["session"] != self.session_id:
                query.reply_err(
                    json.dumps({"code": "wrong_session", "message": "not me", "robot": self.name})
                )
                return
            with self.lock:
                self._acknowledged(up.get("downlink_ack", 0))
                for entry in sorted(up["commands"], key=lambda e: e["seq"]):
                    if entry["seq"] <= self.applied:
                        continue  # processed already: "the server sends every pending command"
                    self.applied = entry["seq"]
                    self.outbox.append(self._answer(entry))
                receipt = {"session": self.session_id, "applied": self.applied}
            query.reply(query.key_expr, json.dumps(receipt))
        self.wake.set()

    def _answer(self, entry: dict) -> dict:
        cmd = entry["command"]
        answer = {"op": "answer", "robot": self.name, "command": entry["seq"], "at": _now()}
        if entry.get("cancel"):
            answer |= {"outcome": "cancelled"}
        elif cmd["cmd"] == "enqueue":
            ids = [s["id"] for s in cmd["skills"] if s["id"] not in self.done]
            if self.partial:
                ids = ids[:1]
            self.enqueued += cmd["skills"]
            new = [i for i in ids if i not in self.queue]
            self.queue = new + self.queue if cmd.get("front") else self.queue + new
            answer |= {"outcome": "applied", "queued": ids}
        elif cmd["cmd"] == "dequeue":
            removed = [i for i in cmd["ids"] if i in self.queue or i not in self.done]
            self.queue = [i for i in self.queue if i not in cmd["ids"]]
            kept = [i for i in cmd["ids"] if i in self.done]
            answer |= {"outcome": "applied", "removed": removed, "kept": kept}
        elif cmd["cmd"] in ("run", "pause", "stop"):
            self.run_mode = cmd["cmd"] == "run"
            answer |= {"outcome": "applied"}
        elif cmd["cmd"] == "reset":
            answer |= {"outcome": "applied", "removed": self.queue}
            self.queue, self.run_mode = [], False
        else:
            answer |= {"outcome": "refused", "reason": f"unknown command {cmd['cmd']}"}
        self.seq += 1  # "one sequence for reports and answers"
        return answer | {"seq": self.seq}

    def _on_world(self, query: zenoh.Query) -> None:
        with query:
            query.reply(query.key_expr, json.dumps({"known": False, "data": {}}))

    # -- the worker: registration, execution, the downlink ----------------------------
    def _work(self) -> None:
        while not self.closing:
            self.wake.wait(0.5)
            self.wake.clear()
            if self.closing:
                return
            with self.lock:
                register = self.must_register
            if register:
                self.register()
            with self.lock:
                if self.registered and self.run_mode and self.queue:
                    sid = self.queue.pop(0)
                    self.report(sid, "running")
                    self.report(sid, "success")
                    self.done.append(sid)
                    self.wake.set()
                flush = self.registered and bool(self.outbox)
            if flush:
                self.flush()

    def register(self, queue: list[str] | None = None) -> dict | None:
        with self.lock:
            self.must_register = False
            request = {
                "manifest": self.manifest,
                "session": self.session_id,
                "queue": [
                    {"id": i, "status": "idle_synchronized"}
                    for i in (self.queue if queue is None else queue)
                ],
                "downlink": list(self.outbox),
                "last_seq": self.seq,
                "uplink_applied": self.applied,
                "sent": _now(),
            }
        reply = self.ask(f"{V}/server/register/{self.name}", request)
        with self.lock:
            if reply is None:
                self.must_register = True
                return None
            self.register_reply = reply
            if reply["accepted"]:
                self._acknowledged(reply["last_seq"])
                self.seq = max(self.seq, reply["last_seq"])
                self.registered = True
            self.lock.notify_all()
        return reply

    def report(self, sid: str, status: str, seq: int | None = None) -> dict:
        if seq is None:
            self.seq += 1
            seq = self.seq
        message = {
            "op": "report",
            "robot": self.name,
            "seq": seq,
            "id": sid,
            "status": status,
            "at": _now(),
        }
        self.outbox.append(message)
        return message

    def flush(self, messages: list[dict] | None = None) -> dict | None:
        with self.lock:
            downlink = {
                "robot": self.name,
                "session": self.session_id,
                "messages": sorted(
                    self.outbox if messages is None else messages, key=lambda m: m["seq"]
                ),
                "uplink_applied": self.applied,
                "sent": _now(),
            }
        ack = self.ask(f"{V}/server/downlink/{self.name}", downlink)
        if ack is not None:
            with self.lock:
                self.acks.append(ack)
                self._acknowledged(ack["last_seq"])
                self.refused += ack.get("refused", [])
                self.lock.notify_all()
        return ack

    def _acknowledged(self, last_seq: int) -> None:
        self.outbox = [m for m in self.outbox if m["seq"] > last_seq]

    def ask(self, key: str, message: dict | str) -> dict | None:
        """One query; its OK reply as a dict; None when refused (kept in `errors`)."""
        payload = message if isinstance(message, str) else json.dumps(message)
        for reply in self.session.get(key, payload=payload, timeout=5.0):
            if reply.ok is not None:
                return json.loads(reply.ok.payload.to_bytes())
            with self.lock:
                self.errors.append(json.loads(reply.err.payload.to_bytes()))
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
    made: list[WireRobot] = []

    def make(name: str = "lru1", skills: dict[str, str] = LRU_SCIENCE, **kw) -> WireRobot:
        made.append(WireRobot(cluster.endpoint, name, skills, **kw))
        return made[-1]

    yield make
    for robot in made:
        try:
            robot.close()
        finally:
            close_session(robot.session)


async def until(robot: WireRobot, predicate, what: str) -> None:
    assert await asyncio.to_thread(robot.wait_until, predicate), f"{robot.name}: {what} within 10 s"


async def online(c, name: str = "lru1") -> None:
    await c.wait_for(lambda _m: name in c.robots and c.robots[name].online, 10)


async def registered(robot: WireRobot) -> dict:
    await until(robot, lambda: robot.register_reply is not None, "no RegisterReply")
    return robot.register_reply


def alerts_of(c) -> list:
    seen: list = []
    c.add_listener(lambda e: seen.append(e.alert) if isinstance(e, AlertRaised) else None)
    return seen


def held_on_ground(m, robot: str) -> list[str]:
    """What the ground shows as on the robot (queued or active)."""
    return [s.id for s in m.tasks[robot] if s.status.value not in ("idle", "success", "failure")]


def test_a_robot_built_from_the_doc_registers_syncs_and_runs(cluster, robots):
    robot = robots()

    async def scenario(c):
        reply = await registered(robot)
        assert reply["accepted"] is True and reply["last_seq"] == 0
        await online(c)
        assert c.robots["lru1"].manifest.skills == LRU_SCIENCE  # FleetEvent carries the manifest
        done = await c.submit(Sync(robot="lru1", through="lru1-1"))  # returns before the robot
        assert done.value["state"] == "queued" and done.value["skills"] == ["lru1-1"]
        m = await c.wait_for(lambda m: status(m, "lru1-1") == "idle_synchronized", 10)
        assert status(m, "lru1-2") == "idle" and robot.queue == ["lru1-1"]
        assert m.command(done.value["command"]).state.value == "acked"
        [sent] = robot.enqueued
        assert sent["id"] == "lru1-1" and sent["skill"] == "drive_to"
        await c.submit(Control(op="run", robot="lru1"))
        m = await c.wait_for(lambda m: status(m, "lru1-1") == "success", 10)
        skill = m.find("lru1-1")[2]
        assert skill.started_at is not None and skill.finished_at is not None  # Report.at
        await until(robot, lambda: robot.outbox == [], "messages unacknowledged")
        assert robot.seq == 4 and robot.refused == [] and robot.errors == []
        assert c.robots["lru1"].delay_s is not None  # from the `sent` of its messages

    drive(cluster, scenario)


def test_partial_ids_the_ground_shows_only_what_the_robot_holds(cluster, robots):
    robot = robots()
    robot.partial = True

    async def scenario(c):
        await registered(robot)
        await online(c)
        alerts = alerts_of(c)
        done = await c.submit(Sync(robot="lru1"))  # lru1-1, lru1-2; it holds only lru1-1
        cmd = await c.wait_command(done.value["command"], 10)
        assert cmd.state.value == "acked" and cmd.done == ["lru1-1"]
        m = c.mission
        assert held_on_ground(m, "lru1") == robot.queue == ["lru1-1"]
        assert status(m, "lru1-2") == "idle"  # not shown as queued: editable again
        await c.wait_for(lambda _m: any("did not queue lru1-2" in a.message for a in alerts), 10)
        alert = next(a for a in alerts if "did not queue" in a.message)
        assert alert.robot == "lru1" and f"command {cmd.id}" in alert.message

    drive(cluster, scenario)


def test_a_seq_gap_is_never_skipped_and_duplicates_apply_once(cluster, robots):
    robot = robots()

    async def scenario(c):
        await registered(robot)
        await online(c)
        await c.submit(Sync(robot="lru1", through="lru1-1"))
        await c.wait_for(lambda m: status(m, "lru1-1") == "idle_synchronized", 10)
        await until(robot, lambda: robot.outbox == [], "the answer unacknowledged")
        alerts = alerts_of(c)
        with robot.lock:  # its report 2 is lost: it sends 3 alone
            running = robot.report("lru1-1", "running")
            success = robot.report("lru1-1", "success")
        ack = await asyncio.to_thread(robot.flush, [success])
        assert ack["last_seq"] == 1 and ack["missing"] == [2, 2]
        m = await c.resync()
        assert status(m.mission, "lru1-1") == "idle_synchronized"  # 3 waits for 2
        await c.wait_for(
            lambda _m: any(a.robot == "lru1" and "not 2" in a.message for a in alerts), 10
        )
        ack = await asyncio.to_thread(robot.flush, [running, success])  # "send again from 2"
        assert ack["last_seq"] == 3
        m = await c.wait_for(lambda m: status(m, "lru1-1") == "success", 10)
        revision = m.revision
        again = await asyncio.to_thread(robot.flush, [running, success])  # sent twice
        assert again["last_seq"] == 3 and again["refused"] == []
        m = await c.resync()
        assert m.revision == revision and m.mission.report_seqs["lru1"] == 3

    drive(cluster, scenario)


def test_registering_twice_and_a_second_process_under_the_same_name(cluster, robots):
    first = robots()

    async def scenario(c):
        await registered(first)
        await online(c)
        await c.submit(Sync(robot="lru1", through="lru1-1"))
        await c.wait_for(lambda m: status(m, "lru1-1") == "idle_synchronized", 10)
        reply = await asyncio.to_thread(first.register)  # the same session again: fine
        assert reply["accepted"] is True and reply["missing"] == []
        assert held_on_ground(c.mission, "lru1") == ["lru1-1"]
        second = robots()  # another process named lru1, while the first is online
        refused = await registered(second)
        assert refused["accepted"] is False and refused["code"] == "taken"
        assert "lru1" in refused["reason"] and "another session" in refused["reason"]
        m = await c.resync()
        assert held_on_ground(m.mission, "lru1") == ["lru1-1"]  # the first one's: untouched
        assert m.robots["lru1"].session == first.session_id
        # a downlink from the refused one is not heard
        with second.lock:
            second.report("lru1-1", "running")
        assert await asyncio.to_thread(second.flush) is None
        assert second.errors[-1]["code"] == "not_registered"
        assert status(c.mission, "lru1-1") == "idle_synchronized"

    drive(cluster, scenario)


def test_garbage_from_the_robot_is_the_robots_fault(cluster, robots):
    robot = robots()

    async def scenario(c):
        await registered(robot)
        await online(c)
        alerts = alerts_of(c)
        bad = await asyncio.to_thread(
            robot.ask, f"{V}/server/downlink/lru1", '{"robot": "lru1", "messages": "??"}'
        )
        assert bad is None
        err = robot.errors[-1]
        assert err["code"] == "bad_message" and err["robot"] == "lru1"
        assert "lru1 sent a downlink that cannot be read" in err["message"]
        await c.wait_for(
            lambda _m: any(a.robot == "lru1" and a.kind == "robot_error" for a in alerts), 10
        )
        # an answer naming skills it was not sent, and one to a command it never got
        done = await c.submit(Sync(robot="lru1", through="lru1-1"))  # operator: no error
        await c.wait_command(done.value["command"], 10)
        with robot.lock:
            robot.seq += 1
            robot.outbox.append(
                {
                    "op": "answer",
                    "robot": "lru1",
                    "seq": robot.seq,
                    "command": 1,
                    "outcome": "applied",
                    "queued": ["lru1-2"],
                }
            )
            robot.seq += 1
            robot.outbox.append(
                {
                    "op": "answer",
                    "robot": "lru1",
                    "seq": robot.seq,
                    "command": 99,
                    "outcome": "applied",
                }
            )
        await asyncio.to_thread(robot.flush)
        m = await c.resync()
        assert status(m.mission, "lru1-2") == "idle"  # never shown as held
        assert m.mission.report_seqs["lru1"] == robot.seq  # consumed, in order
        await c.wait_for(lambda _m: any("command seq 99" in a.message for a in alerts), 10)
        assert all(a.robot == "lru1" for a in alerts)

    drive(cluster, scenario)


def test_unsync_race_answered_by_the_robot(cluster, robots):
    robot = robots()

    async def scenario(c):
        await registered(robot)
        await online(c)
        await c.submit(Sync(robot="lru1"))
        await c.wait_for(lambda m: status(m, "lru1-2") == "idle_synchronized", 10)
        with robot.lock:  # it started lru1-1 meanwhile; the report has not left
            robot.queue.remove("lru1-1")
            robot.done.append("lru1-1")
            robot.report("lru1-1", "running")
            robot.registered = False  # holds its downlink until the dequeue is in
        done = await c.submit(Unsync(robot="lru1"))
        await until(robot, lambda: robot.applied == 2, "the dequeue")
        with robot.lock:
            robot.registered = True
        robot.wake.set()
        cmd = await c.wait_command(done.value["command"], 10)
        assert cmd.kept == ["lru1-1"] and cmd.done == ["lru1-2"]
        m = c.mission
        assert status(m, "lru1-1") == "running" and status(m, "lru1-2") == "idle"

    drive(cluster, scenario)


def test_a_robot_speaking_another_protocol_version_is_told(cluster, robots):
    robot = robots(protocol=1)

    async def scenario(c):
        reply = await registered(robot)
        assert reply["accepted"] is False and reply["code"] == "protocol"
        assert "protocol 2" in reply["reason"]
        snap = await c.resync()
        assert not snap.robots["lru1"].online
        # a version 1 robot asks on the version 1 key: told in version 1's format
        v1 = [
            json.loads(r.ok.payload.to_bytes())
            for r in robot.session.get(
                "mc/v1/server/register/lru1",
                payload=json.dumps({"manifest": robot.manifest, "queue": [], "reports": []}),
                timeout=5.0,
            )
            if r.ok is not None
        ]
        assert v1 and v1[0]["accepted"] is False and "protocol 2" in v1[0]["reason"]

    drive(cluster, scenario)


def test_a_registration_gives_the_library_signature_of_each_skill_offered(cluster, robots):
    robot = robots(skills={"drive_to": "1.0.0", "recharge": "1.0.0", "fly_to": "1.0.0"})

    async def scenario(c):
        skills = (await registered(robot))["skills"]
        assert sorted(skills) == ["drive_to", "recharge"]  # an lru_science does not fly
        assert skills["drive_to"] == {
            "params": {"goal": "pose", "speed": "float", "tolerance": "float"},
            "required": ["goal"],
            "defaults": {"speed": 0.5, "tolerance": 0.5},
        }

    drive(cluster, scenario)


def test_sync_refused_as_incompatible_queues_nothing(cluster, robots):
    robot = robots(skills={k: v for k, v in LRU_SCIENCE.items() if k != "take_science_image"})

    async def scenario(c):
        await registered(robot)
        await online(c)
        with pytest.raises(OperationRefused) as refused:
            await c.submit(Sync(robot="lru1"))
        err = refused.value.reply
        assert err.code == "incompatible" and err.robot == "lru1" and err.skill == "lru1-2"
        assert c.pending() == [] and robot.enqueued == []

    drive(cluster, scenario)


def test_a_restarted_robot_is_told_which_skills_it_lost(cluster, robots):
    first = robots()

    async def scenario(c):
        await registered(first)
        await online(c)
        await c.submit(Sync(robot="lru1", through="lru1-1"))
        await c.wait_for(lambda m: status(m, "lru1-1") == "idle_synchronized", 10)
        first.close()  # it restarts: its queue is gone
        await c.wait_for(lambda _m: not c.robots["lru1"].online, 10)
        again = robots()
        reply = await registered(again)
        assert reply["accepted"] is True and reply["missing"] == ["lru1-1"]
        await c.wait_for(lambda m: status(m, "lru1-1") == "idle", 10)

    drive(cluster, scenario)


def test_a_robot_named_robot_registers(tmp_path):
    """Any valid name works, `robot` too (it is also a chunk of the key space)."""
    lib = ROOT / "missions" / "libraries" / "mars.yaml"
    mission = Path(tmp_path) / "robot.yaml"
    mission.write_text(
        "format: missionctl/mission@1\nname: named robot\n"
        f"library: {lib}\nrobots:\n  robot: {{type: lru_science}}\n"
        "tasks:\n  robot:\n    - {id: r-1, skill: recharge}\n",
        encoding="utf-8",
    )
    cluster = Cluster(tmp_path, str(mission))
    cluster.start_server()
    robot = WireRobot(cluster.endpoint, "robot", LRU_SCIENCE)
    try:

        async def scenario(c):
            assert (await registered(robot))["accepted"] is True
            await online(c, "robot")
            await c.submit(Sync(robot="robot"))
            await c.wait_for(lambda m: status(m, "r-1") == "idle_synchronized", 10)

        drive(cluster, scenario)
    finally:
        robot.close()
        close_session(robot.session)
        cluster.stop()
