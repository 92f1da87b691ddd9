"""The outbox: the robot's downlink. Its reports and its answers to commands
share one sequence and stay here until the server acknowledges them.

Messages leave in sequence order as a `Downlink` whenever the server can
hear us; each one only once the link delay has passed since it was made
(`Link.delay_s`, the simulator's model of a distant robot). The server
applies them strictly in order and acknowledges cumulatively (`last_seq`);
it never skips a gap (`missing`: we send again from there). While out of
reach or unregistered they wait; they also travel with every registration.
With nothing to say, an empty `Downlink` goes out every `heartbeat_s`: the
ground's "heard N s ago" and delay estimate.
"""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime, timedelta

from backend import transport
from backend.agent.runtime import RETRY_S, Runtime, Standing, log
from backend.agent.uplink import CommandLog
from backend.core.ops import Answer, Ask, AskEnded, Report
from backend.protocol.keys import Keys
from backend.protocol.messages import MAX_BATCH, Downlink, DownlinkAck, ErrorReply, dumps
from backend.protocol.timing import HEARTBEAT_S  # until the server's RegisterReply says otherwise
from backend.protocol.wire import parse

Message = Report | Answer | Ask | AskEnded  # the downlink's messages
RANGE_POLL_S = 0.2  # out of range with messages waiting: look again this often


class Outbox:
    """Unacknowledged downlink messages, oldest first, and the task that sends them."""

    def __init__(self, rt: Runtime, standing: Standing, commands: CommandLog):
        self.rt = rt
        self.standing = standing  # sends only while registered
        self.commands = commands  # the uplink's processed commands (each Downlink says how far)
        self.reports: list[Message] = []  # not acknowledged yet, in seq order
        self._ready: dict[int, float] = {}  # seq -> loop time it may leave (made + delay)
        self.refused: list[ErrorReply] = []  # messages the server refused (its reasons)
        self.heartbeat_s = HEARTBEAT_S
        self._last_sent: float | None = None
        self._retry_at: float | None = None
        self._acked: asyncio.Event | None = None  # set whenever an ack removed messages
        self._wake: asyncio.Event | None = None

    def attach(self) -> None:
        """Events on the running loop (start())."""
        self._acked = asyncio.Event()
        self._wake = asyncio.Event()

    def add(self, message: Message) -> None:
        self.reports.append(message)
        loop = self.rt.loop
        self._ready[message.seq] = (loop.time() if loop else 0.0) + self.rt.delay_s()
        self.wake()

    def ack(self, last_seq: int) -> None:
        """The server applied every message up to `last_seq`."""
        before = len(self.reports)
        self.reports = [m for m in self.reports if m.seq > last_seq]
        for seq in [s for s in self._ready if s <= last_seq]:
            del self._ready[seq]
        if len(self.reports) < before and self._acked is not None:
            self._acked.set()

    def renumbered(self, messages: list[Message]) -> None:
        """The same messages under new numbers (registration after a restart)."""
        loop = self.rt.loop
        now = loop.time() if loop else 0.0
        self.reports = messages
        self._ready = {m.seq: now for m in messages}

    def clear(self) -> None:
        """Another run of this robot took over: nothing of ours will be applied."""
        self.reports = []
        self._ready = {}

    def wake(self) -> None:
        """Look again now (a new message, registered, back in range, stopping)."""
        if self._wake is not None:
            self._wake.set()

    async def wait_acknowledged(self, timeout: float | None) -> None:
        if self._acked is None:
            raise self.rt.not_started()
        async with asyncio.timeout(timeout):
            while self.reports:
                self._acked.clear()
                await self._acked.wait()

    # ---------------------------------------------------------------- sending

    def ready(self) -> list[Message]:
        """The messages whose link delay has passed, in order (a prefix)."""
        loop = self.rt.loop
        now = loop.time() if loop else 0.0
        out = []
        for m in self.reports[:MAX_BATCH]:
            if self._ready.get(m.seq, 0.0) > now:
                break
            out.append(m)
        return out

    def _due_in(self) -> float | None:
        """Seconds until there is something to send (None: when woken)."""
        loop = self.rt.loop
        if loop is None or not self.standing.registered:
            return None
        if not self.rt.in_range():
            # looked at again soon: a stay out of range may be shorter than
            # the link loop's poll, which would then not wake us
            return RANGE_POLL_S if self.reports else None
        now = loop.time()
        times = [self._retry_at] if self._retry_at is not None else []
        if self._retry_at is None:
            if self.reports:
                times.append(self._ready.get(self.reports[0].seq, now))
            times.append((self._last_sent or now) + self.heartbeat_s)
        return max(0.0, min(times) - now)

    async def run(self) -> None:
        """Send whenever something is due, until the agent stops."""
        wake = self._wake
        assert wake is not None and self.rt.loop is not None
        while not self.rt.closing:
            try:
                await asyncio.wait_for(wake.wait(), self._due_in())
            except TimeoutError:
                pass
            wake.clear()
            if self.rt.closing or not self.standing.registered or not self.rt.in_range():
                continue  # registration / the link loop wakes us again
            now = self.rt.loop.time()
            if self._retry_at is not None and now < self._retry_at:
                continue
            ready = self.ready()
            heartbeat = self._last_sent is None or now - self._last_sent >= self.heartbeat_s
            if not ready and not heartbeat:
                continue
            try:
                again = await self.send(ready)
                self._retry_at = None
            except asyncio.CancelledError:
                raise
            except Exception as exc:
                log.info("%s: downlink failed (%s); retrying", self.rt.name, exc)
                self._retry_at = self.rt.loop.time() + RETRY_S
                again = False
            if again:
                wake.set()

    async def flush_before_stop(self) -> None:
        """Best effort, briefly: the agent is stopping."""
        if self.reports and self.standing.registered and self.rt.in_range():
            try:
                await asyncio.wait_for(self.send(self.ready()), 1.0)
            except Exception:  # best effort only
                pass

    async def send(self, messages: list[Message]) -> bool:
        """One Downlink; True when the server asks for more at once (a gap)."""
        assert self.rt.session is not None and self.rt.loop is not None
        self._last_sent = self.rt.loop.time()
        downlink = Downlink(
            robot=self.rt.name,
            session=self.rt.session_id,
            messages=messages,
            uplink_applied=self.commands.applied,
            # it left the robot one link delay before it reaches the ground
            sent=datetime.now(UTC) - timedelta(seconds=self.rt.delay_s()),
        )
        try:
            raw = await transport.query(
                self.rt.session,
                Keys.downlink(self.rt.name),
                dumps(downlink),
                timeout=self.rt.robot.request_timeout,
            )
        except transport.QueryError as exc:
            self._refused(exc.payload)
            raise
        ack = parse(DownlinkAck, raw)
        self.refused.extend(ack.refused)
        for refusal in ack.refused:
            log.warning("%s: the server refused a message: %s", self.rt.name, refusal.message)
        self.ack(ack.last_seq)
        return bool(ack.missing) and bool(self.ready())

    def _refused(self, payload: bytes) -> None:
        try:
            err = parse(ErrorReply, payload)
        except ValueError:
            return
        if err.code == "not_registered":
            self.standing.lost()
        else:
            self.rt.say_once(
                f"downlink {err.code}", f"the server refused the downlink: {err.message}"
            )
