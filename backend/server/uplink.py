"""Transmitting a robot's uplink: its pending commands, in order, until the
robot has answered each one.

Each transmission is one `Uplink` query carrying every pending command of
the robot (the robot applies each once, by its seq, and skips the ones it
has processed already), one transmission at a time per robot. The robot's
`UplinkReceipt` says it got them: the commands that were `queued` are
`sent` from then on (journaled after the transmission: until then a cancel
of them waits for its outcome, see `Rules.transmitting`). A refusal
(`unreachable`: out of range), no responder or another session's receipt
means not delivered: they stay `queued` and are tried again, sooner at first.
No answer at all means they may have arrived: `sent`.

When to transmit: a command was queued or cancelled, the robot registered
or its downlink shows it is reachable (`kick`), a retry is due, or the
robot has not answered a sent command for a while (sent again; harmless).
"""

from __future__ import annotations

import asyncio
import logging
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
from backend.protocol.wire import parse
from backend.server.refusals import JournalFailed
from backend.transport import QueryTimeout, TransportError, query_all

log = logging.getLogger(__name__)

SEND_TIMEOUT_S = 5.0  # a receipt is immediate: this is a dead link
RETRY_S = 0.5  # first retry of an undelivered transmission, doubling up to RETRY_MAX_S
RETRY_MAX_S = 5.0
RESEND_SENT_S = 30.0  # sent, not answered: sent again (at least 3 one-way delays later)

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

    def delay_of(self, robot: str) -> float | None: ...

    def submit(self, op: Any, *, actor: str) -> Applied: ...

    def said_once(self, robot: str, what: str, message: str, level: Level = "warning") -> None: ...


def entry(c: UplinkCommand) -> UplinkEntry:
    return UplinkEntry(
        seq=c.seq, id=c.id, expires=c.expires, cancel=c.cancel_requested, command=c.command
    )


class UplinkSender:
    """One robot's transmitter (a task on the server's loop)."""

    def __init__(self, link: LinkView, robot: str):
        self.link = link
        self.robot = robot
        self._wake = asyncio.Event()
        self._retry = RETRY_S
        self._next: float | None = None  # loop time of the next try (None: when woken)
        self._task: asyncio.Task[None] | None = None
        self.transmissions = 0  # for tests and benchmarks

    def start(self) -> None:
        self._task = asyncio.get_running_loop().create_task(
            self._run(), name=f"uplink-{self.robot}"
        )

    def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            self._task = None

    def kick(self) -> None:
        """Transmit now (a new command, a cancel, the robot is reachable)."""
        self._retry = RETRY_S
        self._wake.set()

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            timeout = None if self._next is None else max(0.0, self._next - loop.time())
            try:
                await asyncio.wait_for(self._wake.wait(), timeout)
            except TimeoutError:
                pass
            self._wake.clear()
            try:
                await self._send_once()
            except asyncio.CancelledError:
                raise
            except JournalFailed:  # alerted by the server; the commands stay queued
                self._later(RETRY_MAX_S)
            except Exception:  # a bug must not end the robot's uplink
                log.exception("uplink of %s failed; trying again", self.robot)
                self._later(RETRY_MAX_S)

    def _later(self, seconds: float | None) -> None:
        loop = asyncio.get_running_loop()
        self._next = None if seconds is None else loop.time() + seconds

    async def _send_once(self) -> None:
        pending = self.link.engine.mission.pending_commands(self.robot)
        owner = self.link.owner(self.robot)
        if not pending or owner is None:
            self._later(None)  # woken by a new command or a registration
            return
        queued = [c.id for c in pending if c.state == CommandState.QUEUED]
        outcome = await self._transmit(pending, owner, queued)
        now = _now()
        if outcome in ("delivered", "maybe") and queued:
            self.link.submit(UplinkSent(robot=self.robot, ids=queued, at=now), actor="server")
        elif queued:
            withdrawn = [
                c.id for c in pending if c.id in queued and c.cancel_requested
            ]  # asked while on the way, and it never arrived
            if withdrawn:
                self.link.submit(
                    UplinkSettle(
                        robot=self.robot,
                        ids=withdrawn,
                        state=CommandState.CANCELLED,
                        reason=f"cancelled before it reached {self.robot}",
                        at=now,
                    ),
                    actor="server",
                )
        if outcome == "delivered":
            self._retry = RETRY_S
            delay = self.link.delay_of(self.robot) or 0.0
            self._later(max(RESEND_SENT_S, 3 * delay))
        else:
            self._later(self._retry)
            self._retry = min(self._retry * 2, RETRY_MAX_S)

    async def _transmit(
        self, pending: list[UplinkCommand], owner: str, queued: list[int]
    ) -> Outcome:
        engine = self.link.engine
        up = Uplink(
            robot=self.robot,
            session=owner,
            commands=[entry(c) for c in pending],
            downlink_ack=engine.mission.report_seqs.get(self.robot, 0),
            sent=_now(),
        )
        engine.transmitting.update(queued)
        self.transmissions += 1
        try:
            replies = await query_all(
                self.link.session, Keys.uplink(self.robot), dumps(up), SEND_TIMEOUT_S
            )
        except QueryTimeout:
            return "maybe"
        except TransportError as e:  # the server's session is closing
            log.info("uplink of %s: %s", self.robot, e)
            return "undelivered"
        finally:
            engine.transmitting.difference_update(queued)
        return self._judge(replies, owner)

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
