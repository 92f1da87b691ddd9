"""Transmitting a robot's uplink: its pending commands, in order, until the
robot has answered each one.

Each transmission is one `Uplink` query carrying every pending command of
the robot, in seq order (the robot applies each once, by its seq, and skips
the ones it has processed already). Transmissions are pipelined: something
the robot has not been told (a new command, a cancel) leaves at once in a
transmission of its own, whatever earlier ones still wait for their receipt
(a round trip later: minutes for a distant robot). As each carries every
pending command, the robot meets them in seq order whichever it reads first.

The robot's `UplinkReceipt` says it got them: the commands that were
`queued` are `sent` from then on (journaled once the receipt is in, with
the time the transmission left; until then a cancel of them waits for its
outcome, see `Rules.transmitting`). A refusal (`unreachable`: out of
range), no responder or another session's receipt means not delivered:
they stay `queued` and are tried again, sooner at first. No receipt within
the query timeout (`query_timeout_s`, from the expected one-way delay)
means they may have arrived: `sent`.

When to transmit: at once when a pending command was not transmitted yet
or its cancel is new, and when the robot registers (`resend`: everything);
when its downlink shows it can hear us after a transmission did not reach
it (`reachable`); when a retry is due; or when a sent command has not been
answered for a while (sent again; harmless).
"""

from __future__ import annotations

import asyncio
import logging
from collections import Counter
from datetime import UTC, datetime
from typing import Any, Literal, Protocol

from pydantic import ValidationError

from backend.core.alerts import Level
from backend.core.limits import echo
from backend.core.model import CommandState, UplinkCommand
from backend.core.ops import UplinkSent, UplinkSettle
from backend.core.rules.engine import Applied, Engine
from backend.protocol.keys import Keys
from backend.protocol.messages import (
    ErrorReply,
    Uplink,
    UplinkEntry,
    UplinkReceipt,
    dumps,
    first_error,
)
from backend.protocol.timing import (
    RETRY_MAX_S,
    RETRY_S,
    query_timeout_s,
    resend_after_s,
)
from backend.protocol.wire import parse
from backend.server.refusals import JournalFailed
from backend.transport import QueryTimeout, TransportError, query_all

log = logging.getLogger(__name__)

MAX_IN_FLIGHT = 32  # transmissions under way per robot; more wait for one to end

Outcome = Literal["delivered", "maybe", "undelivered", "absent"]


def _now() -> datetime:
    return datetime.now(UTC)


class LinkView(Protocol):
    """What a sender needs from the robot link."""

    @property
    def engine(self) -> Engine: ...

    @property
    def session(self) -> Any: ...

    def owner(self, robot: str) -> str | None:
        """The registered session of an online robot, else None."""
        ...

    def delay_of(self, robot: str) -> float | None:
        """The expected one-way delay to the robot, in seconds (None: unknown)."""
        ...

    def submit(self, op: Any, *, actor: str) -> Applied: ...

    def said_once(self, robot: str, what: str, message: str, level: Level = "warning") -> None: ...


def entry(c: UplinkCommand) -> UplinkEntry:
    return UplinkEntry(
        seq=c.seq, id=c.id, expires=c.expires, cancel=c.cancel_requested, command=c.command
    )


class UplinkSender:
    """One robot's transmitter (a task on the server's loop, and one task
    per transmission under way)."""

    def __init__(self, link: LinkView, robot: str):
        self.link = link
        self.robot = robot
        self._wake = asyncio.Event()
        self._retry = RETRY_S
        self._due: float | None = None  # loop time of the next timed transmission
        self._told: dict[int, bool] = {}  # command id -> `cancel` it was last transmitted with
        self._missed = False  # the last transmission to end did not reach the robot
        self._flight: Counter[int] = Counter()  # queued command id -> transmissions carrying it
        self._task: asyncio.Task[None] | None = None
        self._sending: set[asyncio.Task[None]] = set()
        self.transmissions = 0  # for tests and benchmarks

    def start(self) -> None:
        self._task = asyncio.get_running_loop().create_task(
            self._run(), name=f"uplink-{self.robot}"
        )

    def stop(self) -> None:
        for task in [self._task, *self._sending]:
            if task is not None:
                task.cancel()
        self._task = None
        self._sending.clear()  # (each one's end still releases what it carried)

    def kick(self) -> None:
        """A command was added or cancelled: what the robot was not told leaves now."""
        self._wake.set()

    def resend(self) -> None:
        """The robot registered (a new session may hold nothing): everything, now."""
        self._told.clear()
        self._retry = RETRY_S
        self._wake.set()

    def reachable(self) -> None:
        """The robot can hear us: a transmission that did not reach it is tried now."""
        if self._missed:
            self._retry = RETRY_S
            self._due = 0.0
            self._wake.set()

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            full = len(self._sending) >= MAX_IN_FLIGHT  # (a transmission ending wakes us)
            timeout = None if self._due is None or full else max(0.0, self._due - loop.time())
            try:
                await asyncio.wait_for(self._wake.wait(), timeout)
            except TimeoutError:
                pass
            self._wake.clear()
            try:
                self._maybe_transmit(loop.time())
            except Exception:  # a bug must not end the robot's uplink
                log.exception("uplink of %s failed; trying again", self.robot)
                self._later(RETRY_MAX_S)

    def _maybe_transmit(self, now: float) -> None:
        pending = self.link.engine.mission.pending_commands(self.robot)
        owner = self.link.owner(self.robot)
        if not pending or owner is None:
            self._due = None  # woken by a new command or a registration
            return
        if not self._worth_sending(pending, now):
            return
        self._due = None
        self._told = {c.id: c.cancel_requested for c in pending}
        task = asyncio.get_running_loop().create_task(
            self._transmit(pending, owner), name=f"uplink-{self.robot}-{self.transmissions + 1}"
        )
        self._sending.add(task)
        task.add_done_callback(self._ended)

    def _worth_sending(self, pending: list[UplinkCommand], now: float) -> bool:
        """Room in flight, and something the robot was not told yet (a
        command, a cancel) or a timed transmission due."""
        if len(self._sending) >= MAX_IN_FLIGHT:
            return False
        if self._due is not None and now >= self._due:
            return True
        return any(self._told.get(c.id) != c.cancel_requested for c in pending)

    def _ended(self, task: asyncio.Task[None]) -> None:
        self._sending.discard(task)
        self._wake.set()

    def _later(self, seconds: float) -> None:
        """A timed transmission in `seconds` (or sooner, if one is due sooner)."""
        at = asyncio.get_running_loop().time() + seconds
        self._due = at if self._due is None else min(self._due, at)

    async def _transmit(self, pending: list[UplinkCommand], owner: str) -> None:
        queued = [c.id for c in pending if c.state == CommandState.QUEUED]
        left = _now()
        try:
            outcome = await self._query(pending, owner, queued)
            self._settle(outcome, pending, queued, left)
        except asyncio.CancelledError:
            raise
        except JournalFailed:  # alerted by the server; the commands stay queued
            self._later(RETRY_MAX_S)
        except Exception:  # a bug must not end the robot's uplink
            log.exception("uplink of %s failed; trying again", self.robot)
            self._later(RETRY_MAX_S)

    def _settle(
        self, outcome: Outcome, pending: list[UplinkCommand], queued: list[int], left: datetime
    ) -> None:
        """Journal what the transmission's outcome says; time the next one."""
        if queued:
            self._journal_outcome(outcome, pending, queued, left)
        self._missed = outcome in ("undelivered", "absent")
        self._time_next(outcome)

    def _journal_outcome(
        self, outcome: Outcome, pending: list[UplinkCommand], queued: list[int], left: datetime
    ) -> None:
        """The queued commands transmitted: sent (or maybe), else those
        cancelled while on the way withdrawn, as they never arrived."""
        if outcome in ("delivered", "maybe"):
            self.link.submit(UplinkSent(robot=self.robot, ids=queued, at=left), actor="server")
            return
        withdrawn = [c.id for c in pending if c.id in queued and c.cancel_requested]
        if withdrawn:
            self.link.submit(
                UplinkSettle(
                    robot=self.robot,
                    ids=withdrawn,
                    state=CommandState.CANCELLED,
                    reason=f"cancelled before it reached {self.robot}",
                    at=_now(),
                ),
                actor="server",
            )

    def _time_next(self, outcome: Outcome) -> None:
        """A delivered transmission is resent after the round trip; any other
        is retried, backing off up to RETRY_MAX_S."""
        if outcome == "delivered":
            self._retry = RETRY_S
            self._later(resend_after_s(self._delay()))
        else:
            self._later(self._retry)
            self._retry = min(self._retry * 2, RETRY_MAX_S)

    def _delay(self) -> float:
        return self.link.delay_of(self.robot) or 0.0

    async def _query(self, pending: list[UplinkCommand], owner: str, queued: list[int]) -> Outcome:
        engine = self.link.engine
        up = Uplink(
            robot=self.robot,
            session=owner,
            commands=[entry(c) for c in pending],
            downlink_ack=engine.mission.report_seqs.get(self.robot, 0),
            sent=_now(),
        )
        self._carry(queued)
        self.transmissions += 1
        try:
            replies = await query_all(
                self.link.session,
                Keys.uplink(self.robot),
                dumps(up),
                query_timeout_s(self._delay()),
            )
        except QueryTimeout:
            return "maybe"
        except TransportError as e:  # the server's session is closing
            log.info("uplink of %s: %s", self.robot, e)
            return "undelivered"
        finally:
            self._landed(queued)
        return self._judge(replies, owner)

    def _carry(self, queued: list[int]) -> None:
        """A transmission carries these queued commands: the engine counts
        them transmitting while any transmission does."""
        for cid in queued:
            if not self._flight[cid]:
                self.link.engine.transmitting.add(cid)
            self._flight[cid] += 1

    def _landed(self, queued: list[int]) -> None:
        """A transmission carrying these ended."""
        for cid in queued:
            self._flight[cid] -= 1
            if not self._flight[cid]:
                del self._flight[cid]
                self.link.engine.transmitting.discard(cid)

    def _judge(self, replies: list[Any], owner: str) -> Outcome:
        """What the replies say: the owner's receipt, a refusal, or nobody."""
        if not replies:
            return "absent"
        outcome: Outcome = "undelivered"
        for r in replies:
            if not r.ok:
                self._refused(r.payload)
                continue
            try:
                receipt = parse(UplinkReceipt, r.payload)
            except ValidationError as e:
                self.link.said_once(
                    self.robot,
                    "receipt",
                    f"{self.robot} answered its uplink with something that is not an "
                    f"UplinkReceipt ({first_error(e)}): the commands may be on it",
                    "error",
                )
                outcome = "maybe"
                continue
            if receipt.session == owner:
                return "delivered"
        return outcome

    def _refused(self, payload: bytes) -> None:
        try:
            err = parse(ErrorReply, payload)
        except ValidationError:
            text = echo(payload.decode(errors="replace"))
            self.link.said_once(
                self.robot, "refusal", f"{self.robot} refused its uplink: {text}", "error"
            )
            return
        if err.code != "unreachable":  # out of range: the usual case, said by the robot's state
            self.link.said_once(
                self.robot, err.code, f"{self.robot} refused its uplink: {err.message}", "error"
            )
