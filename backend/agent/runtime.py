"""What the parts of one agent share: the robot's settable sources, the
asyncio loop every state change runs on, the Zenoh session while started,
safe readings of the integrator's link model, and the robot's standing with
the server (registered or not)."""

from __future__ import annotations

import asyncio
import logging
import secrets
import threading
from collections.abc import Callable
from typing import Any, Protocol

import zenoh

from backend.agent.link import Link
from backend.core.model import Pose
from backend.protocol.messages import Telemetry

# the SDK's logger name is public (integrators configure it): every part logs to it
log = logging.getLogger("backend.agent")

# Retry delay for registration and report flushes that found nobody.
RETRY_S = 0.5


class Robot(Protocol):
    """The parts of a RobotAgent its integrator may set at any time: read live."""

    name: str
    connect: list[str]
    link: Link
    pose: Callable[[], Pose]
    battery: Callable[[], float]
    request_timeout: float

    def telemetry(self) -> Telemetry: ...


class Runtime:
    """One agent's loop, session and link, shared by its parts."""

    def __init__(self, robot: Robot):
        self.robot = robot
        self.name = robot.name
        self.loop: asyncio.AbstractEventLoop | None = None
        self.loop_thread: int | None = None
        self.session: zenoh.Session | None = None
        self.closing = False  # stop() ends the agent's loops
        self.session_id = ""  # this run of the agent (its registration, its presence)
        self._said: set[str] = set()  # keys of the mistakes logged once already

    def attach(self) -> None:
        """Bind to the running loop (start()); a fresh session id."""
        self.loop = asyncio.get_running_loop()
        self.loop_thread = threading.get_ident()
        self.closing = False
        self.session_id = secrets.token_hex(6)

    def post(self, fn: Callable[..., object], *args: Any) -> None:
        """Run `fn(*args)` on the agent's loop (from any thread, never blocks)."""
        loop = self.loop
        if loop is None:
            return
        try:
            loop.call_soon_threadsafe(fn, *args)
        except RuntimeError:  # loop closed
            pass

    def on_loop(self) -> bool:
        return threading.get_ident() == self.loop_thread

    def not_started(self) -> RuntimeError:
        return RuntimeError(
            f"agent {self.name} is not started: call start() (or use async with) first"
        )

    def in_range(self) -> bool:
        try:
            return bool(self.robot.link.in_range())
        except Exception as exc:  # polled 20 times a second: said once
            self.say_once(
                "link.in_range",
                f"agent.link.in_range() failed ({type(exc).__name__}: {exc}); assuming in range",
                exc_info=True,
            )
            return True

    def delay_s(self) -> float:
        """The link's one-way delay."""
        return float(getattr(self.robot.link, "delay_s", 0.0) or 0.0)

    async def delay(self) -> None:
        delay = self.delay_s()
        if delay > 0:
            await asyncio.sleep(delay)  # models the one-way link delay

    def say_once(
        self, key: str, text: str, *, level: int = logging.ERROR, exc_info: bool = False
    ) -> None:
        """Log an integrator's mistake that would otherwise repeat several times a second."""
        if key not in self._said:
            self._said.add(key)
            log.log(level, "%s: %s (said once)", self.name, text, exc_info=exc_info)


class Standing:
    """This run's standing with the current server: the registrar sets it
    (`Registrar`), the outbox sends only while registered and says when the
    server no longer knows us. Events on the running loop (`attach`)."""

    def __init__(self, name: str):
        self.name = name
        self.server_up = False  # the server's presence token is there
        self.registered = False  # the current server accepted this run
        self._wake: asyncio.Event | None = None  # the registrar looks again
        self.answered: asyncio.Event | None = None  # accepted or refused (wait_registered)

    def attach(self) -> None:
        self._wake = asyncio.Event()
        self.answered = asyncio.Event()

    def wake(self) -> None:
        if self._wake is not None:
            self._wake.set()

    async def woken(self) -> None:
        """Return once woken (and clear the wake-up)."""
        assert self._wake is not None
        await self._wake.wait()
        self._wake.clear()

    def unregistered(self) -> None:
        """Not registered with the server any more: wait_registered() waits again."""
        self.registered = False
        if self.answered is not None:
            self.answered.clear()

    def lost(self) -> None:
        """The server does not know us (any more): register again."""
        if self.registered:
            log.warning("%s: the server no longer knows this robot; registering again", self.name)
        self.unregistered()
        self.wake()
