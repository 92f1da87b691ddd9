"""The robot's side of its uplink: commands arrive in the server's `Uplink`
queries, wait one link delay (the model's `Link.delay_s`, see runtime) and
are processed in sequence order, each exactly once:

- a command numbered at or below the last one processed was processed
  already (the server sends every pending command each time): skipped;
- one withdrawn (`cancel`) or past its expiry is not applied: it is
  answered `cancelled` / `expired`;
- any other is applied to the queue, and answered with what the robot
  actually did (`applied` with the ids it queued or removed, or `refused`
  with why).

Each answer is an `Answer` numbered in the same sequence as the reports and
put in the outbox: the ground applies them in that one order. The receipt
of a query only says the commands arrived (or `unreachable`: out of range).
`CommandLog` is the transport-free part (tested like the queue).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Iterable
from datetime import UTC, datetime
from typing import Protocol

from pydantic import ValidationError

from backend.agent.queue import Effect
from backend.agent.runtime import Runtime, log
from backend.core.contingency import POSIX_FROM, clock_text
from backend.core.ops import Answer
from backend.protocol.messages import (
    ErrorReply,
    Uplink,
    UplinkEntry,
    UplinkReceipt,
    dumps,
)
from backend.protocol.wire import parse, unreadable
from backend.transport import ReplyError

Dispatch = Callable[[object], Effect]  # a command -> what the robot did


class Answers(Protocol):
    """Where answers go (the outbox, the robot's downlink): the ground
    acknowledges what it applied of it in each Uplink."""

    def add(self, message: Answer) -> None: ...

    def ack(self, last_seq: int) -> None: ...


def _now() -> datetime:
    return datetime.now(UTC)


def expired_reason(
    now: datetime, expires: datetime, mission_now: float, time_scale: float = 1.0
) -> str:
    """Why a command arrived too late, on the mission clock: a simulator's
    (`it arrived at sim 1:02:00, after its expiry sim 1:00:00`: the wall's
    lateness × `time_scale` before `mission_now`), else the wall's, in UTC."""
    if mission_now >= POSIX_FROM:  # no simulator: the wall's clock, as ever
        return (
            f"it arrived at {now:%H:%M:%S}, after its expiry {expires.astimezone(UTC):%H:%M:%S} UTC"
        )
    late = (now - expires).total_seconds() * (time_scale if time_scale > 0 else 1.0)
    due = clock_text(mission_now - late)
    return f"it arrived at {clock_text(mission_now)}, after its expiry {due}"


class CommandLog:
    """Which commands were processed, and how an entry becomes an answer
    (`mission_time`, `time_scale`: the agent's, read when an entry expires)."""

    def __init__(
        self,
        robot: str,
        mission_time: Callable[[], float] = time.time,
        time_scale: Callable[[], float] = lambda: 1.0,
    ):
        self.robot = robot
        self.applied = 0  # the last uplink seq processed
        self._mission_time = mission_time
        self._time_scale = time_scale

    def due(self, entries: Iterable[UplinkEntry]) -> list[UplinkEntry]:
        """The entries not processed yet, in seq order, each once."""
        seen: set[int] = set()
        out = []
        for e in sorted(entries, key=lambda e: e.seq):
            if e.seq > self.applied and e.seq not in seen:
                seen.add(e.seq)
                out.append(e)
        return out

    def process(self, e: UplinkEntry, dispatch: Dispatch, seq: Callable[[], int]) -> Answer:
        """Apply (or not) one entry; its answer, numbered by `seq()` after
        whatever reports applying it made. Skipped seqs (withdrawn before they
        were ever sent) are not waited for."""
        if e.seq <= self.applied:
            raise ValueError(f"command seq {e.seq} was processed already")
        self.applied = e.seq
        now = _now()
        fields: dict[str, object]
        if e.cancel:
            fields = {"outcome": "cancelled", "reason": "withdrawn before it was applied"}
        elif e.expires is not None and now > e.expires:
            fields = {
                "outcome": "expired",
                "reason": expired_reason(now, e.expires, self._mission_time(), self._time_scale()),
            }
        else:
            change = dispatch(e.command)
            fields = {
                "outcome": "applied" if change.ok else "refused",
                "reason": change.reason,
                "queued": change.queued,
                "removed": change.removed,
                "kept": change.started,
            }
        return Answer.model_validate(
            {"robot": self.robot, "seq": seq(), "command": e.seq, "at": now, **fields}
        )


class UplinkHandler:
    """Receives the Uplink queries and processes their commands on the loop."""

    def __init__(
        self,
        rt: Runtime,
        commands: CommandLog,
        dispatch: Dispatch,
        seq: Callable[[], int],
        downlink: Answers,
    ):
        self.rt = rt
        self.log = commands
        self._dispatch = dispatch
        self._seq = seq
        self._downlink = downlink  # answers go there; each Uplink acknowledges part of it
        self._inbox: list[tuple[float, list[UplinkEntry]]] = []  # (loop time due, entries)
        self._wake: asyncio.Event | None = None
        self.received: list[UplinkEntry] = []  # every entry that arrived (tests, logs)

    def attach(self) -> None:
        self._wake = asyncio.Event()

    def _refusal(self, code: str, message: str) -> ReplyError:
        return ReplyError(dumps(ErrorReply(code=code, message=message, robot=self.rt.name)))

    async def on_uplink(self, payload: bytes) -> bytes:
        """The queryable: a receipt at once; the commands wait their link delay."""
        if not self.rt.in_range():
            raise self._refusal("unreachable", f"{self.rt.name} is out of communication range")
        try:
            up = parse(Uplink, payload)
        except ValidationError as e:
            what = f"the uplink of {self.rt.name}"
            raise self._refusal(*unreadable(e, what, "bad_message")) from None
        mine = self.rt.session_id
        if up.session != mine:
            raise self._refusal(
                "wrong_session",
                f"{self.rt.name} is session {mine}, not {up.session} (a restarted or second "
                "process): it must register first",
            )
        self._downlink.ack(up.downlink_ack)
        self.received.extend(up.commands)
        if up.commands:
            assert self.rt.loop is not None and self._wake is not None
            self._inbox.append((self.rt.loop.time() + self.rt.delay_s(), list(up.commands)))
            self._wake.set()
        return dumps(UplinkReceipt(session=mine, applied=self.log.applied))

    async def run(self) -> None:
        """Process what arrived, in arrival order, each after its delay."""
        wake = self._wake
        assert wake is not None and self.rt.loop is not None
        while not self.rt.closing:
            if not self._inbox:
                await wake.wait()
                wake.clear()
                continue
            due, entries = self._inbox[0]
            wait = due - self.rt.loop.time()
            if wait > 0:
                await asyncio.sleep(wait)  # models the one-way link delay
                continue
            self._inbox.pop(0)
            self.process(entries)

    def process(self, entries: list[UplinkEntry]) -> None:
        for e in self.log.due(entries):
            answer = self.log.process(e, self._dispatch, self._seq)
            log.info(
                "%s: command %d (seq %d) %s%s",
                self.rt.name,
                e.id,
                e.seq,
                answer.outcome,
                f": {answer.reason}" if answer.reason else "",
            )
            self._downlink.add(answer)

    def forget(self) -> None:
        """Another run of this robot took over: drop what has not been processed."""
        self._inbox.clear()
