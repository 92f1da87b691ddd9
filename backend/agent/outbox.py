"""The outbox: every report stays here until the server acknowledges it.

Reports made while out of reach or unregistered wait; they are flushed as a
batch whenever there is something to send and the server can hear us, and
also travel with every command reply and registration. The server applies
them by sequence number, so sending one twice is harmless.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

from backend import transport
from backend.agent.runtime import RETRY_S, Runtime, log
from backend.core.ops import Report
from backend.protocol.keys import Keys
from backend.protocol.messages import ErrorReply, ReportAck, ReportBatch, dumps


class Outbox:
    """Unacknowledged reports, oldest first, and the task that flushes them."""

    def __init__(self, rt: Runtime, registered: Callable[[], bool]):
        self.rt = rt
        self._registered = registered
        self.reports: list[Report] = []
        self.refused: list[ErrorReply] = []  # reports the server refused (its reasons)
        self._acked: asyncio.Event | None = None  # set whenever an ack removed reports
        self._wake: asyncio.Event | None = None

    def attach(self) -> None:
        """Events on the running loop (start())."""
        self._acked = asyncio.Event()
        self._wake = asyncio.Event()

    def add(self, report: Report) -> None:
        self.reports.append(report)

    def ack(self, last_seq: int) -> None:
        """The server applied every report up to `last_seq`."""
        before = len(self.reports)
        self.reports = [r for r in self.reports if r.seq > last_seq]
        if len(self.reports) < before and self._acked is not None:
            self._acked.set()

    def renumbered(self, reports: list[Report]) -> None:
        """The same reports under new numbers (registration after a restart)."""
        self.reports = reports

    def wake(self) -> None:
        """Try to send now (a new report, registered, back in range, stopping)."""
        if self._wake is not None:
            self._wake.set()

    async def wait_acknowledged(self, timeout: float | None) -> None:
        if self._acked is None:
            raise self.rt.not_started()
        async with asyncio.timeout(timeout):
            while self.reports:
                self._acked.clear()
                await self._acked.wait()

    def _can_send(self) -> bool:
        return bool(self.reports) and self._registered() and self.rt.in_range()

    async def run(self) -> None:
        """Flush whenever woken, until the agent stops; retry while nobody answers."""
        wake = self._wake
        assert wake is not None
        while not self.rt.closing:
            await wake.wait()
            wake.clear()
            if not self._can_send():
                continue  # registration / the link loop wakes us again
            try:
                progressed = await self.flush_once()
            except asyncio.CancelledError:
                raise
            except Exception as exc:
                log.info("%s: report flush failed (%s); retrying", self.rt.name, exc)
                progressed = False
            if not self.reports:
                continue
            if progressed:
                wake.set()
            else:
                assert self.rt.loop is not None
                self.rt.loop.call_later(RETRY_S, wake.set)

    async def flush_before_stop(self) -> None:
        """Best effort, briefly: the agent is stopping."""
        if self._can_send():
            try:
                await asyncio.wait_for(self.flush_once(), 1.0)
            except Exception:  # best effort only
                pass

    async def flush_once(self) -> bool:
        """Send the outbox once; True when the ack removed something."""
        assert self.rt.session is not None
        await self.rt.delay()
        if not self.rt.in_range() or not self.reports:
            return False
        raw = await transport.query(
            self.rt.session,
            Keys.reports(self.rt.name),
            dumps(ReportBatch(reports=list(self.reports))),
            timeout=self.rt.robot.request_timeout,
        )
        ack = ReportAck.model_validate_json(raw)
        self.refused.extend(ack.refused)
        for refusal in ack.refused:
            log.warning("%s: the server refused a report: %s", self.rt.name, refusal.message)
        before = len(self.reports)
        self.ack(ack.last_seq)
        return len(self.reports) < before
