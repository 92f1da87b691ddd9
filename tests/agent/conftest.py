"""Fixtures for the robot agent SDK tests.

A Zenoh router runs in a subprocess (the transport tests' helper, on a free
loopback port). In the test process: a FAKE mission server (a client session
with the register/downlink queryables and the server's liveliness token,
which records what it receives, applies the downlink in order by seq and
sends commands on the uplink) and the agents under test, all on the test's
asyncio loop.

`async def` tests run with the shared runner (tests/conftest.py).
Waiting is always on events with a timeout (`Harness.until`), never on sleeps.
"""

from __future__ import annotations

import asyncio
import importlib.util
import secrets
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest
import zenoh

from backend.agent import RobotAgent
from backend.core.library import SkillSignature
from backend.core.model import Policies, SkillInstance, Status
from backend.core.ops import Answer, Ask, AskEnded, Report
from backend.protocol.keys import Keys
from backend.protocol.messages import (
    BarrierInfo,
    Downlink,
    DownlinkAck,
    Enqueue,
    Register,
    RegisterReply,
    Run,
    Uplink,
    UplinkEntry,
    UplinkReceipt,
    dumps,
)
from backend.transport import (
    client_config,
    close_session,
    declare_token,
    open_session,
    query,
    serve_async,
)

WAIT = 10.0  # upper bound for things that normally take milliseconds

# Reuse the transport tests' router helper (tests/transport has no __init__.py,
# so load its conftest by path; only the Router class is used).
_spec = importlib.util.spec_from_file_location(
    "_transport_test_helpers", Path(__file__).resolve().parents[1] / "transport" / "conftest.py"
)
assert _spec is not None and _spec.loader is not None
_helpers = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_helpers)
Router = _helpers.Router


# ---------------------------------------------------------------- fake server


@dataclass
class Reply:
    """A robot's answer to one command, with the reports it made since the
    command was sent (in its downlink before the answer)."""

    answer: Answer
    reports: list[Report]

    @property
    def ok(self) -> bool:
        return self.answer.outcome == "applied"

    @property
    def ids(self) -> list[str]:
        return self.answer.queued + self.answer.removed

    @property
    def kept(self) -> list[str]:
        return self.answer.kept

    @property
    def reason(self) -> str:
        return self.answer.reason


class FakeServer:
    """Stands in for the mission server: registration, the downlink (applied
    strictly in order, like the server), commands on the uplink."""

    def __init__(self, endpoint: str, changed: asyncio.Event):
        self.endpoint = endpoint
        self.changed = changed
        self.session: zenoh.Session | None = None
        self.token: zenoh.LivelinessToken | None = None
        self.registrations: list[Register] = []
        self.batches: list[Downlink] = []
        self.applied: dict[str, list[Report]] = {}  # per robot, in applied order
        self.answers: dict[str, list[Answer]] = {}
        self.asks: dict[str, list[Ask | AskEnded]] = {}  # questions, in applied order
        self.last_seq: dict[str, int] = {}
        self.gaps: list[str] = []  # a seq that did not follow the previous one
        self.refuse: str | None = None  # when set, registrations are refused with this reason
        self.refuse_code: str = "unknown_robot"
        self.sessions: dict[str, str] = {}  # robot -> registered session
        self.uplink_seq: dict[str, int] = {}
        self.pending: dict[str, list[UplinkEntry]] = {}
        self.signatures: dict[str, SkillSignature] = {}  # sent with every accepted registration
        # robot -> how its finished skills ended that others wait for (RegisterReply.outcomes)
        self.outcomes: dict[str, dict[str, Any]] = {}

    async def start(self) -> None:
        self.session = open_session(client_config([self.endpoint]))
        serve_async(self.session, Keys.register("*"), self._on_register)
        serve_async(self.session, Keys.downlink("*"), self._on_downlink)
        self.appear()

    def appear(self) -> None:
        assert self.session is not None
        self.token = declare_token(self.session, Keys.SERVER_ALIVE)

    def vanish(self) -> None:
        if self.token is not None:
            self.token.undeclare()
            self.token = None

    def close(self) -> None:
        if self.session is not None:
            close_session(self.session)

    # -- what robots send -------------------------------------------------
    def apply(self, robot: str, messages: list[Report | Answer | Ask | AskEnded]) -> None:
        for r in sorted(messages, key=lambda m: m.seq):
            if r.robot != robot:
                continue  # not ours (the fake server does not check senders)
            last = self.last_seq.get(robot, 0)
            if r.seq <= last:
                continue  # applied already
            if r.seq != last + 1:
                self.gaps.append(f"{robot}: {last} -> {r.seq}")
                break  # never past a gap
            if isinstance(r, Report):
                self.applied.setdefault(robot, []).append(r)
            elif isinstance(r, Answer):
                self.answers.setdefault(robot, []).append(r)
            else:
                self.asks.setdefault(robot, []).append(r)
            self.last_seq[robot] = r.seq
        self.changed.set()

    async def _on_register(self, payload: bytes) -> bytes:
        reg = Register.model_validate_json(payload)
        self.registrations.append(reg)
        self.changed.set()
        if self.refuse is not None:
            return dumps(RegisterReply(accepted=False, code=self.refuse_code, reason=self.refuse))
        self.sessions[reg.manifest.name] = reg.session
        self.apply(reg.manifest.name, reg.downlink)
        last_seq = self.last_seq.get(reg.manifest.name, 0)
        outcomes = self.outcomes.get(reg.manifest.name, {})
        return dumps(RegisterReply(last_seq=last_seq, skills=self.signatures, outcomes=outcomes))

    async def _on_downlink(self, payload: bytes) -> bytes:
        dl = Downlink.model_validate_json(payload)
        self.batches.append(dl)
        self.apply(dl.robot, dl.messages)
        return dumps(DownlinkAck(last_seq=self.last_seq.get(dl.robot, 0)))

    # -- commands -------------------------------------------------------------
    async def send(self, robot: str, cmd: Any) -> int:
        """Queue a command on `robot`'s uplink and transmit every pending one;
        its seq."""
        assert self.session is not None
        seq = self.uplink_seq[robot] = self.uplink_seq.get(robot, 0) + 1
        self.pending.setdefault(robot, []).append(UplinkEntry(seq=seq, id=seq, command=cmd))
        await self.transmit(robot)
        return seq

    async def transmit(self, robot: str) -> UplinkReceipt:
        assert self.session is not None
        up = Uplink(
            robot=robot,
            session=self.sessions[robot],
            commands=self.pending.get(robot, []),
            downlink_ack=self.last_seq.get(robot, 0),
            sent=datetime.now(UTC),
        )
        raw = await query(self.session, Keys.uplink(robot), dumps(up), timeout=WAIT)
        return UplinkReceipt.model_validate_json(raw)

    async def command(self, robot: str, cmd: Any) -> Reply:
        """Send a command and wait for the robot's answer (in its downlink order)."""
        before = self.last_seq.get(robot, 0)
        seq = await self.send(robot, cmd)
        answer = await self.answer(robot, seq)
        reports = [r for r in self.applied.get(robot, []) if before < r.seq < answer.seq]
        return Reply(answer, reports)

    async def answer(self, robot: str, seq: int) -> Answer:
        async with asyncio.timeout(WAIT):
            while True:
                found = next((a for a in self.answers.get(robot, []) if a.command == seq), None)
                if found is not None:
                    self.pending[robot] = [e for e in self.pending[robot] if e.seq != seq]
                    return found
                self.changed.clear()
                await self.changed.wait()

    async def enqueue(
        self,
        robot: str,
        *skills: SkillInstance,
        front: bool = False,
        barriers: dict[str, BarrierInfo] | None = None,
        kinds: dict[str, dict[str, Any]] | None = None,
    ) -> Reply:
        enqueue = Enqueue(
            skills=list(skills), front=front, barriers=barriers or {}, kinds=kinds or {}
        )
        return await self.command(robot, enqueue)

    # -- inspection --------------------------------------------------------------
    def trail(self, robot: str) -> list[tuple[str, str]]:
        """(skill id, status) of every applied report of `robot`, in order."""
        return [(r.id, r.status.value) for r in self.applied.get(robot, [])]

    def has(self, robot: str, skill_id: str, status: Status, info: str | None = None) -> bool:
        return any(
            r.id == skill_id and r.status == status and (info is None or info in r.info)
            for r in self.applied.get(robot, [])
        )

    def registrations_of(self, robot: str) -> list[Register]:
        return [r for r in self.registrations if r.manifest.name == robot]

    def seqs(self, robot: str) -> list[int]:
        """Downlink numbers of the applied reports (answers take numbers too)."""
        return [r.seq for r in self.applied.get(robot, [])]

    def downlink(self, robot: str) -> list[int]:
        """Downlink numbers of everything applied (reports and answers), in order."""
        msgs = [
            *self.applied.get(robot, []),
            *self.answers.get(robot, []),
            *self.asks.get(robot, []),
        ]
        return sorted(m.seq for m in msgs)


# ---------------------------------------------------------------- harness


class Harness:
    """The fake server plus the agents of one test; `async with` closes all.

    Robot names carry a per-test tag (`name("lru1")` -> "lru1-3fa9c2"): a
    stray robot process of some other run that reconnects to a reused
    loopback port then cannot answer for our robots.
    """

    def __init__(self, endpoint: str):
        self.endpoint = endpoint
        self.tag = secrets.token_hex(3)
        self.changed = asyncio.Event()
        self.server = FakeServer(endpoint, self.changed)
        self.agents: list[RobotAgent] = []
        self.local: dict[str, list[Report]] = {}  # reports as agents made them

    async def __aenter__(self) -> Harness:
        await self.server.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        for agent in self.agents:
            await agent.stop()
        self.server.close()

    def name(self, base: str) -> str:
        return f"{base}-{self.tag}"

    def names(self, *bases: str) -> tuple[str, ...]:
        return tuple(self.name(b) for b in bases)

    def agent(self, name: str, robot_type: str = "rover", **kwargs: Any) -> RobotAgent:
        agent = RobotAgent(name, robot_type, connect=[self.endpoint], **kwargs)
        agent.report_listeners.append(self._on_local_report)
        agent.question_listeners.append(lambda _message: self.changed.set())
        self.agents.append(agent)
        return agent

    def _on_local_report(self, report: Report) -> None:
        self.local.setdefault(report.robot, []).append(report)
        self.changed.set()

    def made(self, robot: str, skill_id: str, status: Status, info: str | None = None) -> bool:
        """Did `robot` make such a report (whether or not the server has it)?"""
        return any(
            r.id == skill_id and r.status == status and (info is None or info in r.info)
            for r in self.local.get(robot, [])
        )

    async def until(
        self, predicate: Callable[[], bool], timeout: float = WAIT, what: str = ""
    ) -> None:
        """Wait until `predicate()` holds; re-checked whenever a report is made or
        received (every state change of interest produces one)."""
        try:
            async with asyncio.timeout(timeout):
                while not predicate():
                    self.changed.clear()
                    await self.changed.wait()
        except TimeoutError:
            raise AssertionError(f"timed out waiting for {what or predicate}") from None

    async def registered(self, *names: str, count: int = 1) -> None:
        """Wait until each named agent registered (at least `count` times)."""
        await self.until(
            lambda: all(len(self.server.registrations_of(n)) >= count for n in names),
            what=f"registration of {names}",
        )
        for n in names:
            await self._agent(n).wait_registered(WAIT)

    async def start(self, *agents: RobotAgent) -> None:
        """Start the agents and wait until each registered."""
        for agent in agents:
            await agent.start()
        await self.registered(*(a.name for a in agents))

    async def run(self, robot: str, *skills: SkillInstance) -> None:
        """Synchronize `skills` to `robot` and put it in run mode."""
        await self.server.enqueue(robot, *skills)
        await self.server.command(robot, Run())

    def _agent(self, name: str) -> RobotAgent:
        return next(a for a in reversed(self.agents) if a.name == name)


def skill(sid: str, name: str = "work", *, retries: int = 0, **params: Any) -> SkillInstance:
    return SkillInstance(
        id=sid,
        skill=name,
        params=params,
        status=Status.IDLE,
        policies=Policies(retries=retries),
    )


@pytest.fixture
def router() -> Iterator[Any]:
    r = Router()
    yield r
    r.proc.stop()


@pytest.fixture
def harness(router: Any) -> Iterator[Harness]:
    """A Harness on the router; any session still open after the test is closed here."""
    h = Harness(router.endpoint)
    yield h
    for agent in h.agents:
        if agent._session is not None:
            close_session(agent._session)
    h.server.close()
