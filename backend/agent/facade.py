"""The robot-side SDK: connect a real or simulated robot to the mission server.
The integrator's guide, with examples a test replays, is docs/robots.md.

    agent = RobotAgent("lru2", "rover", connect=["tcp/127.0.0.1:7447"],
                       modules={"nav": "2.1.0"})
    agent.pose = lambda: current_pose()          # telemetry sources (optional)
    agent.battery = lambda: 0.8

    @agent.skill("drive_to", version="1.0.0")
    async def drive_to(ctx, goal: Pose, speed: float = 0.5):
        while not arrived():
            await ctx.sleep(0.1)                  # honours pause/stop, sim time
            ctx.progress(done_fraction(), eta_s=remaining_s())
        # return None/True: success; Success("what was found"): success with a result
        # text (the report's info); raise SkillFailed("why") or return Failure("why")

    async with agent:                            # start() ... stop()
        await agent.wait_registered(timeout=30)  # RegistrationRefused: the server's reason
        await forever()

Mistakes in setting an agent up (endpoint, names, versions, properties,
handler signatures, a skill registered twice or after start(), a second
process under the same robot name) raise at once with a sentence naming the
robot and skill; a handler that does not fit the parameters it is sent fails
the skill with a reason naming the parameter.

What the agent does (the contract is backend/protocol/messages.py):

- holds the liveliness token `Keys.alive(name)`, answers commands on
  `Keys.command(name)` and robot-to-robot world messages on `Keys.world(name)`,
  publishes `Telemetry`;
- watches the server's token and registers (`Register`: manifest, its queue,
  unacknowledged reports) each time the server appears;
- keeps its synchronized queue itself and executes it with the registered
  handlers; every status change is a numbered `Report` kept in an outbox until
  the server acknowledges it (also attached to every command reply);
- meets its partners at barriers directly through liveliness tokens.

Parameters reach handlers converted by shape (the agent has no skill library;
the server sends normalized values): a mapping with exactly the pose fields
x, y, z, roll, pitch, yaw becomes a `Pose`; one with exactly x, y, z a
`Position`; a list of at least three such mappings (an area) a
`list[Position]`; everything else (marker/robot/str/enum as str, numbers,
lists, dicts) is passed as it came. A `dict` parameter that happens to look
like a position would be converted too: register the skill with `raw=True` to
get plain values, and use `ctx.params` / `ctx.pose(name)` / `ctx.position(name)`.

Behaviour an integrator can rely on:

- The agent starts halted; `run` puts it in run mode, where it executes its
  queue head to tail and stays in run mode when the queue drains (skills
  synchronized later start at once). A failure, `pause`, `stop` or `reset`
  leaves run mode. `run` on a paused skill resumes it.
- `pause` applies to a running skill (reported `paused`); the handler keeps
  going until its next `ctx.checkpoint()` / `ctx.sleep()` / `ctx.check()`,
  where it waits. `pause` while waiting at a barrier is refused (the status
  table has no synchwaiting -> paused): stop instead.
- `stop` cancels the handler at once (an async handler gets CancelledError at
  its current await; a thread handler gets `SkillStopped` from its next
  `ctx.check()`/`ctx.progress()`), reports `idle_synchronized` and puts the
  skill back at the head of the queue; the next `run` starts it afresh.
- Autonomous retries stay `running` with `attempt` + 1 (failure is final).
- Reports are numbered from 1 per agent run, or after the server's
  `RegisterReply.last_seq` when that is higher (a restarted robot).

Threading: every state change runs on the asyncio loop that called `start()`.
Zenoh callbacks only post to that loop. Synchronous handlers run in a daemon
worker thread (so a handler that ignores stop cannot hang interpreter exit);
they may call `ctx.progress()` and `ctx.check()` (blocks while paused, raises
`SkillStopped` once stopped). World ask/tell handlers run on the loop.
"""

from __future__ import annotations

import asyncio
import functools
import inspect
import logging
import re
import threading
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

import zenoh
from pydantic import TypeAdapter, ValidationError

from backend import transport
from backend.agent.link import Link
from backend.agent.outcomes import (
    AlreadyConnected,
    Failure,
    RegistrationRefused,
    SkillFailed,
    SkillStopped,
    Success,
)
from backend.core.library import VERSION_PATTERN
from backend.core.model import NAME_RE, Pose, Position, SkillInstance, Status
from backend.core.ops import Report
from backend.core.params import typed_by_shape
from backend.protocol.keys import Keys
from backend.protocol.messages import (
    BarrierInfo,
    Command,
    CommandReply,
    Dequeue,
    Enqueue,
    ErrorReply,
    Manifest,
    Module,
    Pause,
    QueueEntry,
    Register,
    RegisterReply,
    ReportAck,
    ReportBatch,
    Reset,
    Run,
    Stop,
    Telemetry,
    WorldMessage,
    WorldReply,
    dumps,
    first_error,
)
from backend.transport.login import Login

log = logging.getLogger(
    "backend.agent"
)  # the SDK's logger name is public (integrators configure it)

_COMMAND = TypeAdapter(Command)
_SEMVER = re.compile(VERSION_PATTERN)  # what a library's skill version may be
_MODULE_VERSION = re.compile(r"^\d+\.\d+\.\d+")  # as protocol.Module: a suffix like -rc1 may follow
_ENDPOINT = re.compile(r"^[a-z][a-z0-9\-]*/\S+$")  # PROTOCOL/ADDRESS, as ctl's --connect
_POSE_KEYS = frozenset(Pose.model_fields)
_POSITION_KEYS = frozenset(Position.model_fields)

# How often the link model is polled (it is a plain callable of the integrator).
_LINK_POLL_S = 0.05
# Retry delay for registration and report flushes that found nobody.
_RETRY_S = 0.5
# A barrier partner whose presence token has not shown up by then is offline.
_PRESENCE_GRACE_S = 1.0


# ---------------------------------------------------------------- execution state


@dataclass
class _Entry:
    """A skill the robot holds (queued or active)."""

    skill: SkillInstance
    barrier: BarrierInfo | None = None
    status: Status = Status.IDLE_SYNCHRONIZED
    attempt: int = 1
    retries_used: int = 0

    @property
    def id(self) -> str:
        return self.skill.id


@dataclass
class _Active:
    """The executing entry and everything that must be released when it ends."""

    entry: _Entry
    task: asyncio.Task[None] | None = None
    aborted: bool = False  # stopped/reset: the task must not touch agent state any more
    paused_by_operator: bool = False
    paused_by_comms: bool = False
    # set while not paused; the asyncio one for coroutines, the threading one for threads
    resumed: asyncio.Event = field(default_factory=asyncio.Event)
    resumed_t: threading.Event = field(default_factory=threading.Event)
    pause_requested: asyncio.Event = field(default_factory=asyncio.Event)
    # barrier resources (withdrawn when the skill ends or is stopped)
    barrier_entities: list[Any] = field(default_factory=list)
    barrier_token: zenoh.LivelinessToken | None = None
    result_info: str = ""  # a handler's Success text, reported with `success`

    def __post_init__(self) -> None:
        self.resumed.set()
        self.resumed_t.set()

    @property
    def paused(self) -> bool:
        return self.paused_by_operator or self.paused_by_comms

    def sync_pause_flags(self) -> None:
        if self.paused:
            self.resumed.clear()
            self.resumed_t.clear()
            self.pause_requested.set()
        else:
            self.pause_requested.clear()
            self.resumed.set()
            self.resumed_t.set()


@dataclass(frozen=True)
class _Handler:
    fn: Callable[..., Any]
    version: str
    raw: bool

    @property
    def is_async(self) -> bool:
        return inspect.iscoroutinefunction(self.fn)


# ---------------------------------------------------------------- skill context


def _coroutine_only(method: Callable[..., Any]) -> Callable[..., Any]:
    """A SkillContext coroutine called from a plain-function handler's thread
    would only make a coroutine object nobody awaits: no wait, no pause, no
    answer. Say so instead."""

    @functools.wraps(method)
    def call(self: SkillContext, *args: Any, **kwargs: Any) -> Any:
        if not self._on_loop():
            raise RuntimeError(
                f"ctx.{method.__name__}() is for coroutine handlers (async def); the handler of "
                f"{self.skill.skill} is a plain function running in a thread: use ctx.check() between "
                f"blocking steps, or make it a coroutine"
            )
        return method(self, *args, **kwargs)

    return call


class SkillContext:
    """What a handler gets as its first argument."""

    def __init__(
        self, agent: RobotAgent, act: _Active, params: dict[str, Any], purpose: str = "skill"
    ):
        self.agent = agent
        self._act = act
        self.skill: SkillInstance = act.entry.skill
        self.params: dict[str, Any] = params  # the raw values as sent by the server
        self.attempt: int = act.entry.attempt
        self.purpose = purpose  # "skill" or "recharge" (a recharge run before this skill)

    # -- state -----------------------------------------------------------
    @property
    def stopped(self) -> bool:
        return self._act.aborted

    @property
    def paused(self) -> bool:
        return self._act.paused

    def _on_loop(self) -> bool:
        return threading.get_ident() == self.agent._loop_thread

    # -- progress ----------------------------------------------------------
    def progress(self, fraction: float, info: str = "", eta_s: float | None = None) -> None:
        """Report progress (0..1) for telemetry; callable from handler threads.

        Raises `SkillStopped` once the skill was stopped (handy for sync loops).
        """
        if self._act.aborted:
            raise SkillStopped()
        fraction = min(1.0, max(0.0, float(fraction)))
        info = "" if info is None else str(info)  # it goes into telemetry, which checks its types
        eta_s = None if eta_s is None else float(eta_s)
        if self._on_loop():
            self.agent._set_progress(self._act, fraction, info, eta_s)
        else:
            self.agent._post(self.agent._set_progress, self._act, fraction, info, eta_s)

    # -- pause / stop --------------------------------------------------------
    @_coroutine_only
    async def checkpoint(self) -> None:
        """Return when not paused; raise `SkillStopped` if stopped."""
        while True:
            if self._act.aborted:
                raise SkillStopped()
            if not self._act.paused:
                return
            await self._act.resumed.wait()

    def check(self) -> None:
        """Synchronous checkpoint for handlers running in a thread: blocks while
        paused, raises `SkillStopped` once stopped."""
        if self._on_loop():
            # never block the event loop: an async handler must await checkpoint()
            if self._act.aborted:
                raise SkillStopped()
            if self._act.paused:
                self.agent._say_once(
                    f"check {self.skill.skill}",
                    f"the coroutine handler of {self.skill.skill} calls ctx.check(), which cannot wait on the "
                    f"event loop: it ignores the pause; use await ctx.checkpoint() or await ctx.sleep()",
                    level=logging.WARNING,
                )
            return
        while True:
            if self._act.aborted:
                raise SkillStopped()
            if self._act.resumed_t.wait(0.1):
                if self._act.aborted:
                    raise SkillStopped()
                return

    @_coroutine_only
    async def sleep(self, seconds: float) -> None:
        """Sleep `seconds` of robot time (divided by `agent.time_scale`), not
        counting time spent paused; raises `SkillStopped` when stopped."""
        scale = self.agent.time_scale if self.agent.time_scale > 0 else 1.0
        remaining = max(0.0, float(seconds)) / scale
        loop = asyncio.get_running_loop()
        while True:
            await self.checkpoint()
            if remaining <= 0:
                return
            started = loop.time()
            try:
                # returns early when a pause is requested, else times out
                await asyncio.wait_for(self._act.pause_requested.wait(), remaining)
            except TimeoutError:
                await self.checkpoint()
                return
            remaining -= loop.time() - started

    # -- typed parameters ------------------------------------------------------
    def pose(self, name: str) -> Pose:
        """Parameter `name` as a Pose (a position gets zero orientation)."""
        value = self.params[name]
        if isinstance(value, Pose):
            return value
        if isinstance(value, Position):
            return Pose(**value.model_dump())
        return Pose(**value)

    def position(self, name: str) -> Position:
        """Parameter `name` as a Position (a pose loses its orientation)."""
        value = self.params[name]
        if isinstance(value, Position):
            return value
        if isinstance(value, Pose):
            return Position(x=value.x, y=value.y, z=value.z)
        return Position(**{k: value[k] for k in value if k in _POSITION_KEYS})

    def area(self, name: str) -> list[Position]:
        return [p if isinstance(p, Position) else Position(**p) for p in self.params[name]]

    # -- world -------------------------------------------------------------------
    @_coroutine_only
    async def ask(
        self, robot: str, topic: str, data: dict[str, Any] | None = None
    ) -> dict[str, Any] | None:
        return await self.agent.ask(robot, topic, data)

    @_coroutine_only
    async def tell(self, robot: str, topic: str, data: dict[str, Any] | None = None) -> bool:
        return await self.agent.tell(robot, topic, data)


# ---------------------------------------------------------------- the agent


class RobotAgent:
    """A robot's connection to the mission: registration, queue, execution,
    reports, telemetry, barriers and world messages. See the module docstring."""

    def __init__(
        self,
        name: str,
        robot_type: str,
        *,
        connect: list[str] | str,
        modules: dict[str, str] | None = None,
        properties: dict[str, Any] | None = None,
        lease_ms: int = 1000,
        zenoh_extra: dict[str, Any] | None = None,
        telemetry_hz: float = 2.0,
        request_timeout: float = 5.0,
        login: Login | None = None,
    ):
        _check_name("robot name", name)
        _check_name(f"robot {name}: type", robot_type)
        self.name = name
        self.robot_type = robot_type
        self.connect = _endpoints(name, connect)
        self.modules = dict(modules or {})
        for module, version in self.modules.items():
            _check_name(f"robot {name}: module", module)
            if not isinstance(version, str) or not _MODULE_VERSION.match(version):
                raise ValueError(
                    f"robot {name}: module {module} version {version!r} is not SemVer (like 2.1.0)"
                )
        self.properties = dict(properties or {})
        self.lease_ms = lease_ms
        # an account (robot role) and TLS files: see docs/security.md
        self.zenoh_extra = {**(zenoh_extra or {}), **(login.zenoh_options() if login else {})}
        self.telemetry_hz = telemetry_hz
        self.request_timeout = request_timeout

        # integrator-settable sources and models
        self.pose: Callable[[], Pose] = Pose
        self.battery: Callable[[], float] = lambda: 1.0
        self.link = Link()
        self.time_scale = 1.0

        self._handlers: dict[str, _Handler] = {}
        self._ask_handlers: dict[str, Callable[..., Any]] = {}
        self._tell_handlers: dict[str, Callable[..., Any]] = {}
        # asks/tells that got no answer (unknown robot, out of reach, timeout) count as failed
        self.world_stats = {
            "asks_sent": 0,
            "tells_sent": 0,
            "asks_failed": 0,
            "tells_failed": 0,
            "asks_received": 0,
            "tells_received": 0,
        }
        # called with every Report as it is made (simulator, logs, tests)
        self.report_listeners: list[Callable[[Report], object]] = []

        # queue and execution (loop thread only)
        self._queue: list[_Entry] = []
        self._active: _Active | None = None
        self._run_enabled = False  # halted until `run`
        self._done: set[str] = set()  # finished skill ids (a re-sent enqueue never re-runs them)

        # reports
        self._seq = 0
        self._outbox: list[Report] = []
        self._acked_evt: asyncio.Event | None = None  # set whenever an ack removed reports

        # telemetry fields
        self._mode = "idle"
        self._progress: float | None = None
        self._eta: float | None = None
        self._info = ""

        # connection state
        self._session: zenoh.Session | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._loop_thread: int | None = None
        self._entities: list[Any] = []
        self._token: zenoh.LivelinessToken | None = None
        self._publisher: zenoh.Publisher | None = None
        self._tasks: list[asyncio.Task[None]] = []
        self._server_up = False
        self._registered = False
        self._closing = False
        self._in_range = True
        self._register_wake: asyncio.Event | None = None
        self._flush_wake: asyncio.Event | None = None
        self._registered_evt: asyncio.Event | None = None
        self.last_register_reply: RegisterReply | None = None
        self._refused: str | None = None  # the server's reason, while it refuses us
        self._register_error = ""  # why the last registration attempt got no reply
        self.refused_reports: list[ErrorReply] = []
        # the thread of the last plain-function handler, done once it returned
        self._handler_thread: asyncio.Future[None] | None = None
        self._manifest_bytes()  # what is wrong with it is said now, not by a registration retried forever
        self._said: set[str] = set()  # keys of the mistakes logged once already

    # ------------------------------------------------------------ registration API

    def skill(
        self, name: str, version: str = "1.0.0", *, raw: bool = False
    ) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
        """Decorator: `@agent.skill("drive_to", version="1.0.0")` registers a handler
        `handler(ctx, **params)` (function or coroutine). `raw=True` passes the
        parameter values unconverted."""
        if not isinstance(name, str):  # `@agent.skill` without (): would register nothing
            raise TypeError(
                f'robot {self.name}: write @agent.skill("NAME", version="1.0.0"), with the skill\'s '
                f"name, above {getattr(name, '__name__', name)!r}"
            )

        def register(fn: Callable[..., Any]) -> Callable[..., Any]:
            self.add_skill(name, fn, version=version, raw=raw)
            return fn

        return register

    def add_skill(
        self, name: str, fn: Callable[..., Any], *, version: str = "1.0.0", raw: bool = False
    ) -> None:
        """Register `fn(ctx, **params)` as the handler of skill `name` (see `skill`).
        Before `start()`: the manifest listing the skills is sent then."""
        _check_name(f"robot {self.name}: skill name", name)
        where = f"robot {self.name}, skill {name}"
        if not isinstance(version, str) or not _SEMVER.match(version):
            raise ValueError(f"{where}: version {version!r} is not SemVer (like 1.2.0)")
        if not callable(fn):
            raise TypeError(
                f"{where}: the handler must be a function or coroutine function, not {type(fn).__name__}"
            )
        if not _takes_ctx(fn):
            raise TypeError(
                f"{where}: the handler must take the SkillContext as its first argument, "
                f"like def {getattr(fn, '__name__', 'handler')}(ctx, **params)"
            )
        if name in self._handlers:
            raise ValueError(
                f"{where}: a handler is registered already "
                f"({getattr(self._handlers[name].fn, '__name__', '?')}); register each skill once"
            )
        if self._session is not None:
            raise RuntimeError(
                f"{where}: register skills before start(); the manifest was sent without it"
            )
        self._handlers[name] = _Handler(fn, version, raw)

    def on_ask(self, topic: str, fn: Callable[..., Any]) -> None:
        """`fn(data, sender) -> dict | None` (or a coroutine) answers asks on
        `topic`; None means "unknown". Runs on the agent's loop: keep it short."""
        self._add_world_handler("on_ask", self._ask_handlers, topic, fn)

    def on_tell(self, topic: str, fn: Callable[..., Any]) -> None:
        """`fn(data, sender)` (or a coroutine) receives tells on `topic`."""
        self._add_world_handler("on_tell", self._tell_handlers, topic, fn)

    def _add_world_handler(
        self, kind: str, table: dict[str, Callable[..., Any]], topic: str, fn: Callable[..., Any]
    ) -> None:
        where = f"robot {self.name}, {kind} {topic!r}"
        if not callable(fn):
            raise TypeError(
                f"{where}: the handler must be a function fn(data, sender), not {type(fn).__name__}"
            )
        if topic in table:
            raise ValueError(f"{where}: a handler is registered already; register each topic once")
        table[topic] = fn

    def manifest(self) -> Manifest:
        return Manifest(
            name=self.name,
            type=self.robot_type,
            modules=[Module(name=k, version=v) for k, v in self.modules.items()],
            properties=self.properties,
            skills={k: h.version for k, h in self._handlers.items()},
        )

    def _manifest_bytes(self) -> bytes:
        """The manifest as sent; ValueError naming the robot when it cannot be."""
        try:
            return dumps(self.manifest())
        except ValidationError as exc:
            raise ValueError(
                f"robot {self.name}: the manifest is not valid: {first_error(exc)}"
            ) from None
        except Exception as exc:  # properties pydantic cannot write as JSON
            raise ValueError(
                f"robot {self.name}: the manifest cannot be written as JSON "
                f"(properties must be JSON values): {exc}"
            ) from None

    # ------------------------------------------------------------ introspection

    @property
    def queue(self) -> list[str]:
        """Ids of the queued (not started) skills, in order."""
        return [e.id for e in self._queue]

    @property
    def active(self) -> tuple[str, Status] | None:
        """(id, status) of the active skill, if any."""
        if self._active is None:
            return None
        return self._active.entry.id, self._active.entry.status

    @property
    def pending_reports(self) -> list[Report]:
        """Reports not acknowledged by the server yet."""
        return list(self._outbox)

    @property
    def registered(self) -> bool:
        return self._registered

    def _not_started(self) -> RuntimeError:
        return RuntimeError(
            f"agent {self.name} is not started: call start() (or use async with) first"
        )

    async def wait_acknowledged(self, timeout: float | None = None) -> None:
        """Return once the server acknowledged every report made so far
        (TimeoutError after `timeout` seconds)."""
        if self._acked_evt is None:
            raise self._not_started()
        async with asyncio.timeout(timeout):
            while self._outbox:
                self._acked_evt.clear()
                await self._acked_evt.wait()

    async def wait_registered(self, timeout: float | None = None) -> None:
        """Return once the current server accepted our registration.

        Raises `RegistrationRefused` (the server's reason: not in the mission,
        another type, protocol) and `TimeoutError` after `timeout` seconds,
        both with a message saying why."""
        if self._registered_evt is None:
            raise self._not_started()
        try:
            async with asyncio.timeout(timeout):
                await self._registered_evt.wait()
        except TimeoutError:
            if not self._server_up:
                why = f"no mission server is up behind {', '.join(self.connect)} (its presence token is missing)"
            elif not self._link_in_range():
                why = "the robot is out of communication range (agent.link)"
            else:
                why = f"the server did not accept the registration ({self._register_error or 'no answer yet'})"
            raise TimeoutError(
                f"robot {self.name} not registered within {timeout:g} s: {why}"
            ) from None
        if self._refused is not None and not self._registered:
            raise RegistrationRefused(self._refused)

    # ------------------------------------------------------------ lifecycle

    async def __aenter__(self) -> RobotAgent:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    async def start(self) -> None:
        """Connect, declare everything, and begin registering with the server.

        Raises `transport.TransportUnreachable` when the router is down.
        """
        if self._session is not None:
            raise RuntimeError(f"agent {self.name} is already started")
        self._manifest_bytes()  # properties may have changed since the constructor
        self._loop = asyncio.get_running_loop()
        self._loop_thread = threading.get_ident()
        self._closing = False
        self._register_wake = asyncio.Event()
        self._flush_wake = asyncio.Event()
        self._registered_evt = asyncio.Event()
        self._acked_evt = asyncio.Event()
        self._in_range = self._link_in_range()
        config = transport.client_config(
            self.connect, lease_ms=self.lease_ms, extra=self.zenoh_extra
        )
        session = transport.open_session(config, what=f"the router (for robot {self.name})")
        self._session = session
        try:
            # Before anything is declared: a second agent under this name would
            # also answer the commands and run every skill a second time.
            if await transport.present_tokens(session, Keys.alive(self.name), self.request_timeout):
                raise AlreadyConnected(
                    f"robot {self.name} is already connected (another process holds its presence): stop that one "
                    f"first; a killed one is gone at once, a hung one after its lease ({self.lease_ms} ms)"
                )
            # Queryables first: once the server sees our token, commands must work.
            self._entities.append(
                transport.serve_async(session, Keys.command(self.name), self._on_command)
            )
            self._entities.append(
                transport.serve_async(session, Keys.world(self.name), self._on_world)
            )
            self._publisher = transport.declare_publisher(session, Keys.telemetry(self.name))
            self._token = transport.declare_token(session, Keys.alive(self.name))
            self._tasks = [
                asyncio.create_task(self._registrar(), name=f"{self.name}-register"),
                asyncio.create_task(self._flusher(), name=f"{self.name}-flush"),
                asyncio.create_task(self._telemetry_loop(), name=f"{self.name}-telemetry"),
                asyncio.create_task(self._link_loop(), name=f"{self.name}-link"),
            ]
            self._entities.append(
                transport.transport_events(
                    session, lambda change: self._post(self._on_router_link, change), history=False
                )
            )
            # Last: this may (re)register at once.
            self._entities.append(
                transport.watch_liveliness(
                    session,
                    Keys.SERVER_ALIVE,
                    lambda _key, alive: self._post(self._on_server, alive),
                )
            )
        except BaseException:
            await self.stop()
            raise

    async def stop(self) -> None:
        """Stop executing, try to deliver pending reports briefly, close the session.

        Safe to call twice. No report is made for a skill interrupted here: the
        robot simply goes offline (the server sees its token vanish).
        """
        session = self._session
        if session is None:
            return
        act = self._active
        tasks = list(self._tasks)
        if act is not None:
            self._release(act, abort=True)
            self._active = None
            if act.task is not None and act.task is not asyncio.current_task():
                tasks.append(act.task)
        # The flag and the wake-ups end our loops even if a cancellation gets
        # lost (Python 3.11's wait_for swallows one that races a completion).
        self._closing = True
        for event in (self._register_wake, self._flush_wake):
            if event is not None:
                event.set()
        for task in tasks:
            task.cancel()
        if tasks:
            _done, pending = await asyncio.wait(tasks, timeout=2.0)
            if pending:
                log.warning(
                    "%s: tasks still running at stop: %s",
                    self.name,
                    [t.get_name() for t in pending],
                )
        self._tasks = []
        if self._outbox and self._registered and self._link_in_range():
            try:
                await asyncio.wait_for(self._flush_once(), 1.0)
            except Exception:  # best effort only
                pass
        self._session = None
        self._registered = False
        self._server_up = False
        self._entities.clear()
        self._token = None
        self._publisher = None
        # Closing undeclares every entity and token; without it the process
        # would hang at exit (callback subscribers keep it alive).
        transport.close_session(session)

    # ------------------------------------------------------------ loop helpers

    def _post(self, fn: Callable[..., object], *args: Any) -> None:
        """Run `fn(*args)` on the agent's loop (from any thread, never blocks)."""
        loop = self._loop
        if loop is None:
            return
        try:
            loop.call_soon_threadsafe(fn, *args)
        except RuntimeError:  # loop closed
            pass

    def _link_in_range(self) -> bool:
        try:
            return bool(self.link.in_range())
        except Exception as exc:  # polled 20 times a second: said once
            self._say_once(
                "link.in_range",
                f"agent.link.in_range() failed ({type(exc).__name__}: {exc}); assuming in range",
                exc_info=True,
            )
            return True

    async def _delay(self) -> None:
        delay = float(getattr(self.link, "delay_s", 0.0) or 0.0)
        if delay > 0:
            await asyncio.sleep(delay)  # models the one-way link delay

    # ------------------------------------------------------------ server presence & registration

    def _on_router_link(self, change: transport.TransportChange) -> None:
        # Zenoh reconnects by itself; the server's token then reappears and we
        # register again. Logged because commands fail meanwhile.
        if change.connected:
            log.info("%s: connected to %s %s", self.name, change.whatami, change.zid)
        else:
            log.warning(
                "%s: lost the link to %s %s; reconnecting", self.name, change.whatami, change.zid
            )

    def _on_server(self, alive: bool) -> None:
        self._server_up = alive
        # A (re)appearing server may be a new instance: always register again.
        self._registered = False
        if self._registered_evt is not None:
            self._registered_evt.clear()
        if alive and self._register_wake is not None:
            self._register_wake.set()

    def _queue_entries(self) -> list[QueueEntry]:
        out = []
        if self._active is not None:
            out.append(QueueEntry(id=self._active.entry.id, status=self._active.entry.status))
        out += [QueueEntry(id=e.id, status=e.status) for e in self._queue]
        return out

    async def _registrar(self) -> None:
        assert self._register_wake is not None
        while not self._closing:
            await self._register_wake.wait()
            self._register_wake.clear()
            if not self._server_up or self._registered or not self._link_in_range():
                continue  # the link loop / server watcher wakes us again
            try:
                await self._register_once()
            except asyncio.CancelledError:
                raise
            except transport.NoResponder:
                # the server's token is there but its register queryable is not:
                # the router's access control dropped the query
                if not getattr(self, "_warned_unanswered", False):  # once, not every retry
                    self._warned_unanswered = True
                    log.warning(
                        "%s: the server is up but %s gets no answer: does the robot account "
                        "(--user) list this robot? retrying",
                        self.name,
                        Keys.register(self.name),
                    )
                assert self._loop is not None
                self._loop.call_later(_RETRY_S, self._register_wake.set)
            except Exception as exc:
                self._register_error = str(exc) or type(exc).__name__
                log.info("%s: registration failed (%s); retrying", self.name, exc)
                assert self._loop is not None
                self._loop.call_later(_RETRY_S, self._register_wake.set)

    async def _register_once(self) -> None:
        assert self._session is not None
        await self._delay()
        request = Register(
            manifest=self.manifest(), queue=self._queue_entries(), reports=list(self._outbox)
        )
        raw = await transport.query(
            self._session, Keys.register(self.name), dumps(request), timeout=self.request_timeout
        )
        reply = RegisterReply.model_validate_json(raw)
        self.last_register_reply = reply
        if not reply.accepted:
            log.error("%s: the server refused the registration: %s", self.name, reply.reason)
            self._refused = f"the mission server refused robot {self.name}: {reply.reason}"
            assert self._registered_evt is not None
            self._registered_evt.set()  # wait_registered() raises it
            return  # tried again when the server (re)appears
        self._refused = None
        if reply.last_seq > self._seq:
            # The server applied reports of a previous run of this robot with
            # higher numbers: ours would be ignored as duplicates. Renumber the
            # unacknowledged ones after it (none of them can have been applied,
            # as the server never saw a number this high from us).
            self._outbox = [
                r.model_copy(update={"seq": reply.last_seq + 1 + i})
                for i, r in enumerate(self._outbox)
            ]
            self._seq = reply.last_seq + len(self._outbox)
        else:
            self._ack(reply.last_seq)
        if reply.missing:
            log.warning(
                "%s: the server holds skills this robot does not know: %s", self.name, reply.missing
            )
        self._registered = True
        assert self._registered_evt is not None
        self._registered_evt.set()
        self._wake_flush()

    # ------------------------------------------------------------ reports

    def _report(self, entry: _Entry, status: Status, info: str = "") -> Report:
        """Record a status change: numbered report into the outbox, telemetry out."""
        self._seq += 1
        entry.status = status
        report = Report(
            robot=self.name,
            seq=self._seq,
            id=entry.id,
            status=status,
            info=info,
            attempt=entry.attempt,
            at=datetime.now(UTC),
        )
        self._outbox.append(report)
        self._info = info
        self._update_mode()
        for listener in list(self.report_listeners):
            try:
                listener(report)
            except Exception:
                log.exception("%s: report listener failed", self.name)
        self._publish_telemetry()
        self._wake_flush()
        return report

    def _ack(self, last_seq: int) -> None:
        before = len(self._outbox)
        self._outbox = [r for r in self._outbox if r.seq > last_seq]
        if len(self._outbox) < before and self._acked_evt is not None:
            self._acked_evt.set()

    def _wake_flush(self) -> None:
        if self._flush_wake is not None:
            self._flush_wake.set()

    async def _flusher(self) -> None:
        assert self._flush_wake is not None
        while not self._closing:
            await self._flush_wake.wait()
            self._flush_wake.clear()
            if not self._outbox or not self._registered or not self._link_in_range():
                continue  # registration / the link loop wakes us again
            try:
                progressed = await self._flush_once()
            except asyncio.CancelledError:
                raise
            except Exception as exc:
                log.info("%s: report flush failed (%s); retrying", self.name, exc)
                progressed = False
            if self._outbox:
                assert self._loop is not None
                if progressed:
                    self._flush_wake.set()
                else:
                    self._loop.call_later(_RETRY_S, self._flush_wake.set)

    async def _flush_once(self) -> bool:
        """Send the outbox once; True when the ack removed something."""
        assert self._session is not None
        await self._delay()
        if not self._link_in_range() or not self._outbox:
            return False
        batch = list(self._outbox)
        raw = await transport.query(
            self._session,
            Keys.reports(self.name),
            dumps(ReportBatch(reports=batch)),
            timeout=self.request_timeout,
        )
        ack = ReportAck.model_validate_json(raw)
        if ack.refused:
            self.refused_reports.extend(ack.refused)
            for refusal in ack.refused:
                log.warning("%s: the server refused a report: %s", self.name, refusal.message)
        before = len(self._outbox)
        self._ack(ack.last_seq)
        return len(self._outbox) < before

    # ------------------------------------------------------------ telemetry

    def _update_mode(self) -> None:
        if self._active is not None:
            status = self._active.entry.status
            # just taken from the queue, not reported yet: "starting"
            self._mode = "starting" if status == Status.IDLE_SYNCHRONIZED else status.value
        elif self._queue:
            self._mode = "running" if self._run_enabled else "halted"
        else:
            self._mode = "idle"

    def _set_progress(self, act: _Active, fraction: float, info: str, eta_s: float | None) -> None:
        if act is not self._active or act.aborted:
            return
        self._progress = fraction
        self._eta = eta_s
        if info:
            self._info = info

    def _say_once(
        self, key: str, text: str, *, level: int = logging.ERROR, exc_info: bool = False
    ) -> None:
        """Log an integrator's mistake that would otherwise repeat several times a second."""
        if key not in self._said:
            self._said.add(key)
            log.log(level, "%s: %s (said once)", self.name, text, exc_info=exc_info)

    def _source_failed(self, what: str, problem: str) -> None:
        """A telemetry source failed: the telemetry goes on with a default."""
        self._say_once(
            f"source {what}", f"{problem}; telemetry sends a default instead", exc_info=True
        )

    def telemetry(self) -> Telemetry:
        # An integrator's source must never break a command reply or a report
        # (both publish telemetry): a bad value is replaced, and said once.
        try:
            pose = self.pose()
            if not isinstance(pose, Pose):
                pose = Pose.model_validate(pose)  # a dict of pose fields will do
        except Exception as exc:
            self._source_failed(
                "pose",
                f"agent.pose() must return a backend.core.model.Pose: {type(exc).__name__}: {exc}",
            )
            pose = Pose()
        try:
            battery = min(1.0, max(0.0, float(self.battery())))
        except Exception as exc:
            self._source_failed(
                "battery", f"agent.battery() must return a number 0..1: {type(exc).__name__}: {exc}"
            )
            battery = 0.0
        try:
            quality = min(1.0, max(0.0, float(getattr(self.link, "quality", 1.0))))
        except Exception as exc:
            self._source_failed(
                "link", f"agent.link.quality must be a number 0..1: {type(exc).__name__}: {exc}"
            )
            quality = 0.0
        act = self._active
        in_range = self._link_in_range()
        return Telemetry(
            robot=self.name,
            pose=pose,
            battery=battery,
            link=quality if in_range else 0.0,
            in_range=in_range,
            mode=self._mode,
            skill=act.entry.id if act is not None else None,
            progress=self._progress if act is not None else None,
            eta_s=self._eta if act is not None else None,
            info=self._info,
            at=datetime.now(UTC),
        )

    def _publish_telemetry(self) -> None:
        if self._publisher is None or not self._link_in_range():
            return  # out of range: the operator cannot hear us
        payload = dumps(self.telemetry())
        delay = float(getattr(self.link, "delay_s", 0.0) or 0.0)
        if delay > 0 and self._loop is not None:
            # the ground sees the robot as it was one link delay ago
            self._loop.call_later(delay, self._put_telemetry, payload)
        else:
            self._put_telemetry(payload)

    def _put_telemetry(self, payload: bytes) -> None:
        publisher = self._publisher
        if publisher is None:
            return  # stopped meanwhile
        try:
            publisher.put(payload)
        except Exception:
            log.exception("%s: cannot publish telemetry", self.name)

    async def _telemetry_loop(self) -> None:
        period = 1.0 / self.telemetry_hz if self.telemetry_hz > 0 else None
        if period is None:
            return
        while not self._closing:
            self._publish_telemetry()
            await asyncio.sleep(period)

    # ------------------------------------------------------------ link

    async def _link_loop(self) -> None:
        """Poll the link model; act on range changes."""
        while not self._closing:
            await asyncio.sleep(_LINK_POLL_S)
            now = self._link_in_range()
            if now == self._in_range:
                continue
            self._in_range = now
            log.info("%s: %s communication range", self.name, "back in" if now else "out of")
            self._apply_comms_policy()
            if now:
                assert self._register_wake is not None
                self._register_wake.set()
                self._wake_flush()
                self._publish_telemetry()

    def _apply_comms_policy(self) -> None:
        """policies.pause_out_of_comms: pause the running skill while out of range."""
        act = self._active
        if act is None or act.aborted or not act.entry.skill.policies.pause_out_of_comms:
            return
        status = act.entry.status
        in_range = self._link_in_range()
        if not in_range and not act.paused_by_comms and status in (Status.RUNNING, Status.PAUSED):
            act.paused_by_comms = True
            act.sync_pause_flags()
            if status == Status.RUNNING:
                self._report(act.entry, Status.PAUSED, "paused: out of communication range")
        elif in_range and act.paused_by_comms:
            act.paused_by_comms = False
            act.sync_pause_flags()
            if not act.paused:
                self._report(act.entry, Status.RUNNING, "resumed: back in communication range")

    # ------------------------------------------------------------ commands

    async def _on_command(self, payload: bytes) -> bytes:
        if not self._link_in_range():
            raise self._unreachable()
        await self._delay()
        if not self._link_in_range():
            raise self._unreachable()
        try:
            cmd = _COMMAND.validate_json(payload)
        except ValidationError as exc:
            raise transport.Refusal(
                dumps(
                    ErrorReply(
                        code="bad_request",
                        message=f"{self.name} cannot read the command: {exc}",
                        robot=self.name,
                    )
                )
            ) from None
        # Everything below is synchronous: no other command or skill step
        # interleaves, and the reply carries every report made so far.
        if isinstance(cmd, Enqueue):
            reply = self._cmd_enqueue(cmd)
        elif isinstance(cmd, Dequeue):
            reply = self._cmd_dequeue(cmd)
        elif isinstance(cmd, Run):
            reply = self._cmd_run()
        elif isinstance(cmd, Pause):
            reply = self._cmd_pause()
        elif isinstance(cmd, Stop):
            reply = self._cmd_stop()
        elif isinstance(cmd, Reset):
            reply = self._cmd_reset()
        else:  # pragma: no cover - the discriminated union is exhaustive
            raise transport.Refusal(
                dumps(ErrorReply(code="bad_request", message="unknown command"))
            )
        self._update_mode()
        self._publish_telemetry()
        reply.reports = list(self._outbox)
        return dumps(reply)

    def _unreachable(self) -> transport.Refusal:
        return transport.Refusal(
            dumps(
                ErrorReply(
                    code="unreachable",
                    message=f"{self.name} is out of communication range",
                    robot=self.name,
                )
            )
        )

    def _known(self, skill_id: str) -> _Entry | None:
        if self._active is not None and self._active.entry.id == skill_id:
            return self._active.entry
        return next((e for e in self._queue if e.id == skill_id), None)

    def _cmd_enqueue(self, cmd: Enqueue) -> CommandReply:
        unknown = sorted({s.skill for s in cmd.skills if s.skill not in self._handlers})
        if unknown:
            return CommandReply(
                ok=False,
                reason=f"{self.name} has no handler for skill {', '.join(unknown)} "
                f"(it offers: {', '.join(sorted(self._handlers)) or 'none'})",
            )
        new: list[_Entry] = []
        ids: list[str] = []
        for s in cmd.skills:
            if s.id in self._done:
                continue  # a re-sent enqueue: it ran already
            ids.append(s.id)
            if self._known(s.id) is not None or any(e.id == s.id for e in new):
                continue  # a re-sent enqueue: it is queued already
            skill = s.model_copy(update={"status": Status.IDLE_SYNCHRONIZED})
            new.append(_Entry(skill=skill, barrier=cmd.barriers.get(s.id), attempt=s.attempt))
        self._queue = new + self._queue if cmd.front else self._queue + new
        self._kick()
        return CommandReply(ids=ids)

    def _cmd_dequeue(self, cmd: Dequeue) -> CommandReply:
        wanted = set(cmd.ids)
        removed = [e.id for e in self._queue if e.id in wanted]
        self._queue = [e for e in self._queue if e.id not in wanted]
        # Started meanwhile (active or finished): the unsync race; the server
        # learns their status from the reports attached to this reply.
        kept = [
            i
            for i in cmd.ids
            if i in self._done or (self._active is not None and self._active.entry.id == i)
        ]
        # Ids we never had cannot run either: report them as removed.
        removed += [i for i in cmd.ids if i not in removed and i not in kept]
        return CommandReply(ids=removed, kept=kept)

    def _cmd_run(self) -> CommandReply:
        self._run_enabled = True
        act = self._active
        if act is not None and act.paused_by_operator:
            act.paused_by_operator = False
            act.sync_pause_flags()
            if not act.paused:
                self._report(act.entry, Status.RUNNING, "resumed")
            return CommandReply()
        if act is None and not self._queue:
            # Stays in run mode: skills synchronized later start at once.
            return CommandReply(
                reason=f"{self.name} has nothing queued; it will run what is synchronized next"
            )
        self._kick()
        return CommandReply()

    def _cmd_pause(self) -> CommandReply:
        act = self._active
        if act is not None and act.entry.status == Status.SYNCHWAITING:
            return CommandReply(
                ok=False,
                reason=f"{self.name} is waiting at a barrier with {act.entry.id}; only a running skill can be paused (stop it instead)",
            )
        self._run_enabled = False
        if act is None:
            return CommandReply(reason=f"{self.name} has no running skill; its queue is halted")
        if not act.paused_by_operator:
            was_running = act.entry.status == Status.RUNNING
            act.paused_by_operator = True
            act.sync_pause_flags()
            if was_running:
                self._report(act.entry, Status.PAUSED, "paused by operator")
        return CommandReply()

    def _cmd_stop(self) -> CommandReply:
        self._run_enabled = False
        if self._active is None:
            return CommandReply(reason=f"{self.name} has no active skill; its queue is halted")
        entry = self._stop_active("stopped by operator")
        self._queue.insert(0, entry)
        return CommandReply()

    def _cmd_reset(self) -> CommandReply:
        self._run_enabled = False
        removed: list[str] = []
        if self._active is not None:
            removed.append(self._stop_active("reset by operator").id)
        removed += [e.id for e in self._queue]
        self._queue = []
        return CommandReply(ids=removed)

    # ------------------------------------------------------------ execution

    def _kick(self) -> None:
        """Start the next queued skill if running and idle."""
        if (
            not self._run_enabled
            or self._active is not None
            or not self._queue
            or self._session is None
        ):
            return
        entry = self._queue.pop(0)
        act = _Active(entry)
        self._active = act
        self._progress = None
        self._eta = None
        self._update_mode()
        act.task = asyncio.get_running_loop().create_task(
            self._execute(act), name=f"{self.name}-{entry.id}"
        )

    def _stop_active(self, info: str) -> _Entry:
        """Stop the active skill now (synchronously): handler cancelled, barrier
        token withdrawn, `idle_synchronized` reported. Returns its entry."""
        act = self._active
        assert act is not None
        self._release(act, abort=True)
        self._active = None
        entry = act.entry
        if entry.status != Status.IDLE_SYNCHRONIZED:
            self._report(entry, Status.IDLE_SYNCHRONIZED, info)
        return entry

    def _release(self, act: _Active, *, abort: bool) -> None:
        if abort:
            act.aborted = True
            act.resumed.set()  # wake waiters so they see the stop
            act.resumed_t.set()
            # not the task we run in: a handler calling `await agent.stop()` would
            # be cancelled inside stop(), before the session is closed
            if (
                act.task is not None
                and not act.task.done()
                and act.task is not asyncio.current_task()
            ):
                act.task.cancel()
        for entity in act.barrier_entities:
            try:
                entity.undeclare()
            except Exception:
                pass
        act.barrier_entities.clear()
        if act.barrier_token is not None:
            try:
                act.barrier_token.undeclare()
            except Exception:
                pass
            act.barrier_token = None

    def _finish(self, act: _Active, status: Status, info: str) -> None:
        self._release(act, abort=False)
        self._active = None
        self._done.add(act.entry.id)
        if status == Status.FAILURE:
            self._run_enabled = False  # the operator decides: retry, run (continue) or unsync
        self._report(act.entry, status, info)
        self._kick()

    async def _execute(self, act: _Active) -> None:
        entry = act.entry
        try:
            start_info = ""
            recharge = await self._maybe_recharge(act)
            if act.aborted:
                return
            if recharge is not None:  # the recharge failed: the skill fails
                self._finish(act, Status.FAILURE, recharge)
                return
            if entry.barrier is not None:
                await self._wait_barrier(act)
                if act.aborted:
                    return
                start_info = f"barrier {entry.barrier.barrier}: all partners ready"
            retries = entry.skill.policies.retries
            while True:
                if act.paused:
                    # paused between attempts: the retry starts once resumed
                    await act.resumed.wait()
                    if act.aborted:
                        return
                self._report(entry, Status.RUNNING, start_info)
                self._apply_comms_policy()
                reason = await self._call_handler(act)
                if act.aborted:
                    return
                if reason is None:
                    self._finish(act, Status.SUCCESS, act.result_info)
                    return
                if entry.retries_used >= retries:
                    self._finish(act, Status.FAILURE, reason)
                    return
                # Autonomous retry: stays `running` with the next attempt
                # (failure is final, so it is never reported in between).
                entry.retries_used += 1
                entry.attempt += 1
                # ctx.skill.attempt agrees with ctx.attempt and the reports
                entry.skill = entry.skill.model_copy(update={"attempt": entry.attempt})
                self._progress = None
                start_info = f"retry {entry.retries_used}/{retries} after: {reason}"
        except asyncio.CancelledError:
            if act.aborted or self._session is None:
                return  # stopped / agent stopping: whoever cancelled reported it
            raise
        except Exception as exc:  # a bug in the SDK itself: never leave the skill hanging
            log.exception("%s: executing %s failed", self.name, entry.id)
            if not act.aborted and self._active is act:
                self._finish(act, Status.FAILURE, f"agent error: {type(exc).__name__}: {exc}")

    async def _maybe_recharge(self, act: _Active) -> str | None:
        """policies.recharge_below: run the `recharge` handler first when the
        battery is low. Returns a failure reason, or None."""
        threshold = act.entry.skill.policies.recharge_below
        if (
            threshold is None
            or "recharge" not in self._handlers
            or act.entry.skill.skill == "recharge"
        ):
            return None
        try:
            level = float(self.battery())
        except Exception:
            log.exception("%s: agent.battery() failed", self.name)
            return None
        if level >= threshold:
            return None
        # Report it under the skill's own status: synchwaiting for a barrier skill
        # (it is not ready yet), running otherwise.
        status = Status.SYNCHWAITING if act.entry.barrier is not None else Status.RUNNING
        self._report(
            act.entry, status, f"recharging first: battery {level:.0%} below {threshold:.0%}"
        )
        reason = await self._call_handler(act, purpose="recharge")
        if reason is not None:
            return f"recharge before the skill failed: {reason}"
        return None

    async def _call_handler(self, act: _Active, purpose: str = "skill") -> str | None:
        """Run the handler once. None = success, else the failure reason.
        Cancellation (stop) propagates."""
        name = "recharge" if purpose == "recharge" else act.entry.skill.skill
        handler = self._handlers[name]
        raw_params = dict(act.entry.skill.params) if purpose == "skill" else {}
        params = (
            raw_params if handler.raw else {k: typed_by_shape(v) for k, v in raw_params.items()}
        )
        ctx = SkillContext(self, act, raw_params, purpose)
        mismatch = _signature_problem(handler.fn, params)
        if mismatch is not None:  # else a bare TypeError from inside the call
            log.error("%s: skill %s (%s): %s", self.name, act.entry.id, name, mismatch)
            return mismatch
        straggler = self._handler_thread
        if straggler is not None and not straggler.done():
            # A plain-function handler that ignored a stop still runs in its
            # thread: two handlers would drive the robot at once.
            log.warning(
                "%s: the handler of the stopped skill has not returned (it never calls ctx.check()); "
                "%s waits for it before starting",
                self.name,
                act.entry.id,
            )
            self._set_progress(act, 0.0, "waiting for the stopped skill's handler to return", None)
            await asyncio.shield(straggler)
        try:
            if handler.is_async:
                result = await handler.fn(ctx, **params)
            else:
                result, self._handler_thread = _in_daemon_thread(handler.fn, ctx, **params)
                result = await result
                if inspect.isawaitable(result):  # a sync function returning a coroutine
                    result = await result
        except SkillFailed as exc:
            return str(exc.reason) or "skill failed"
        except asyncio.CancelledError:
            if act.aborted or self._session is None:
                raise
            # The handler cancelled itself (e.g. a SkillStopped it raised
            # without a stop): a failure, not a stop.
            return "the handler was cancelled"
        except Exception as exc:
            # a bug in the handler: the operator gets one line, the robot's log the traceback
            log.error(
                "%s: the handler of %s (%s) raised", self.name, act.entry.id, name, exc_info=True
            )
            return f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        if isinstance(result, Failure):
            return str(result.reason) or "skill failed"
        if isinstance(result, Success) and purpose == "skill":
            act.result_info = str(result.info)
        if result is False:
            return "the handler returned False"
        return None

    # ------------------------------------------------------------ barriers

    async def _wait_barrier(self, act: _Active) -> None:
        """Wait (synchwaiting) until every partner's ready token is present."""
        assert self._session is not None and act.entry.barrier is not None
        info = act.entry.barrier
        session = self._session
        partners = sorted(p for p in info.partners if p != self.name)
        ready: set[str] = set()
        met = [False]
        online: dict[str, bool | None] = dict.fromkeys(partners)  # None: not known yet
        changed = asyncio.Event()

        def on_ready(key: str, alive: bool) -> None:
            robot = key.rsplit("/", 1)[-1]
            (ready.add if alive else ready.discard)(robot)
            # Judge in event order: a fast partner may start, finish and
            # withdraw its token before this loop looks again; it was ready.
            if all(p in ready for p in partners):
                met[0] = True
            changed.set()

        def on_alive(robot: str, alive: bool) -> None:
            online[robot] = alive
            changed.set()

        def presence_deadline() -> None:
            # The subscriber's history reports a present token within
            # milliseconds but never says "absent": no token by now = offline.
            for p in partners:
                if online[p] is None:
                    online[p] = False
            changed.set()

        if not partners:
            return  # a barrier of one robot: nothing to wait for
        self._report(act.entry, Status.SYNCHWAITING, "waiting for " + ", ".join(partners))
        # Order matters (race-free): subscribe to the partners' ready tokens
        # (with history) BEFORE declaring ours. A partner starts only after it
        # saw our token, and withdraws its own only after starting; so its
        # token is either already there when we subscribe (history) or appears
        # later (live): we cannot miss it. Declaring first could let a fast
        # partner see us, start and withdraw before our subscription existed.
        act.barrier_entities.append(
            transport.watch_liveliness(
                session,
                Keys.barrier_ready(info.barrier, "*"),
                lambda key, alive: self._post(on_ready, key, alive),
            )
        )
        act.barrier_token = transport.declare_token(
            session, Keys.barrier_ready(info.barrier, self.name)
        )
        for p in partners:
            act.barrier_entities.append(
                transport.watch_liveliness(
                    session, Keys.alive(p), lambda _k, alive, p=p: self._post(on_alive, p, alive)
                )
            )
        deadline = asyncio.get_running_loop().call_later(_PRESENCE_GRACE_S, presence_deadline)
        try:
            reported_offline: tuple[str, ...] = ()
            while True:
                missing = [p for p in partners if p not in ready]
                if met[0] or not missing:
                    return  # our token stays until the skill ends (see _release)
                offline = tuple(p for p in missing if online[p] is False)
                if offline:
                    text = "waiting for " + ", ".join(f"{p} (offline)" for p in offline)
                else:
                    text = "waiting for " + ", ".join(missing)
                # Report again whenever a partner goes offline or comes back;
                # other changes only update telemetry (no report flood).
                if offline != reported_offline:
                    self._report(act.entry, Status.SYNCHWAITING, text)
                    reported_offline = offline
                elif text != self._info:
                    self._info = text
                    self._publish_telemetry()
                # all state changes happen on this loop: clearing here loses nothing
                changed.clear()
                await changed.wait()
        finally:
            deadline.cancel()

    # ------------------------------------------------------------ world

    async def _on_world(self, payload: bytes) -> bytes:
        try:
            msg = WorldMessage.model_validate_json(payload)
        except ValidationError as exc:
            raise transport.Refusal(
                dumps(
                    ErrorReply(
                        code="bad_request",
                        message=f"{self.name} cannot read the world message: {exc}",
                    )
                )
            ) from None
        if msg.kind == "ask":
            self.world_stats["asks_received"] += 1
            fn = self._ask_handlers.get(msg.topic)
            data = await self._world_handler("on_ask", fn, msg) if fn is not None else None
            if data is None:
                return dumps(WorldReply(known=False))
            if not isinstance(data, dict):
                raise self._world_refusal(
                    msg,
                    f"its on_ask handler returned a {type(data).__name__}; it must return a dict or None",
                )
            return dumps(WorldReply(known=True, data=data))
        self.world_stats["tells_received"] += 1
        fn = self._tell_handlers.get(msg.topic)
        if fn is not None:
            await self._world_handler("on_tell", fn, msg)
        return dumps(WorldReply(known=fn is not None))

    async def _world_handler(self, kind: str, fn: Callable[..., Any], msg: WorldMessage) -> Any:
        try:
            return await _maybe_await(fn(msg.data, msg.sender))
        except Exception as exc:
            raise self._world_refusal(
                msg, f"its {kind} handler raised {type(exc).__name__}: {exc}", trace=True
            ) from None

    def _world_refusal(
        self, msg: WorldMessage, problem: str, trace: bool = False
    ) -> transport.Refusal:
        """Logged here; the asker's `ask`/`tell` fails (None/False) and its log says why."""
        text = f"{self.name} cannot answer {msg.kind} {msg.topic!r} from {msg.sender}: {problem}"
        log.error("%s", text, exc_info=trace)
        return transport.Refusal(
            dumps(ErrorReply(code="robot_error", message=text, robot=self.name))
        )

    async def _world_query(
        self, robot: str, kind: str, topic: str, data: dict[str, Any] | None
    ) -> WorldReply | None:
        if self._session is None:
            raise self._not_started()
        msg = WorldMessage(kind=kind, sender=self.name, topic=topic, data=dict(data or {}))  # type: ignore[arg-type]
        try:
            reachable = (
                bool(self.link.can_reach(robot)) if hasattr(self.link, "can_reach") else True
            )
        except Exception:
            log.exception("%s: link.can_reach(%s) failed; assuming reachable", self.name, robot)
            reachable = True
        if not reachable:
            log.info(
                "%s: %s %s/%s not sent: %s is out of reach", self.name, kind, robot, topic, robot
            )
            return None
        try:
            raw = await transport.query(
                self._session, Keys.world(robot), dumps(msg), timeout=self.request_timeout
            )
            return WorldReply.model_validate_json(raw)
        except (transport.QueryFailed, transport.TransportError, ValidationError) as exc:
            why = str(exc)
            if isinstance(exc, transport.QueryError):  # the robot's refusal: say its sentence
                try:
                    why = ErrorReply.model_validate_json(exc.payload).message
                except ValidationError:
                    pass
            log.info("%s: %s %s/%s failed: %s", self.name, kind, robot, topic, why)
            return None

    async def ask(
        self, robot: str, topic: str, data: dict[str, Any] | None = None
    ) -> dict[str, Any] | None:
        """Ask `robot` about `topic`; its answer, or None (unknown / unreachable)."""
        self.world_stats["asks_sent"] += 1
        reply = await self._world_query(robot, "ask", topic, data)
        if reply is None:
            self.world_stats["asks_failed"] += 1
        return reply.data if reply is not None and reply.known else None

    async def tell(self, robot: str, topic: str, data: dict[str, Any] | None = None) -> bool:
        """Tell `robot` something; True when it was delivered to a handler."""
        self.world_stats["tells_sent"] += 1
        reply = await self._world_query(robot, "tell", topic, data)
        if reply is None:
            self.world_stats["tells_failed"] += 1
        return reply is not None and reply.known


# ---------------------------------------------------------------- helpers


async def _maybe_await(value: Any) -> Any:
    return await value if inspect.isawaitable(value) else value


def _in_daemon_thread(
    fn: Callable[..., Any], *args: Any, **kwargs: Any
) -> tuple[Awaitable[Any], asyncio.Future[None]]:
    """Like asyncio.to_thread, but in a daemon thread: a sync handler that never
    checks for stop keeps running, yet cannot keep the process from exiting.
    Returns the result and a future done when the thread has returned (also
    after the result was cancelled)."""
    loop = asyncio.get_running_loop()
    future: asyncio.Future[Any] = loop.create_future()
    returned: asyncio.Future[None] = loop.create_future()

    def settle(ok: bool, value: Any) -> None:
        returned.done() or returned.set_result(None)
        if future.done():
            return  # cancelled (stopped) meanwhile
        if ok:
            future.set_result(value)
        else:
            future.set_exception(value)

    def run() -> None:
        try:
            result = fn(*args, **kwargs)
        except BaseException as exc:  # noqa: BLE001 - handed to the awaiting task
            outcome = (False, exc)
        else:
            outcome = (True, result)
        try:
            loop.call_soon_threadsafe(settle, *outcome)
        except RuntimeError:
            pass  # loop closed

    threading.Thread(
        target=run, name=f"skill-{getattr(fn, '__name__', 'handler')}", daemon=True
    ).start()
    return future, returned


def _endpoints(robot: str, connect: list[str] | str) -> list[str]:
    """The router endpoints, checked here: Zenoh's own complaint names neither
    the robot nor the form it wants."""
    endpoints = [connect] if isinstance(connect, str) else list(connect)
    if not endpoints:
        raise ValueError(
            f"robot {robot}: connect lists no endpoint; give the mission server's, like tcp/127.0.0.1:7447"
        )
    for e in endpoints:
        if not isinstance(e, str) or not _ENDPOINT.match(e):
            raise ValueError(
                f"robot {robot}: connect endpoint {e!r} is not PROTOCOL/ADDRESS, like tcp/127.0.0.1:7447"
            )
    return endpoints


def _takes_ctx(fn: Callable[..., Any]) -> bool:
    """Can `fn` be called with the SkillContext as its first positional argument?"""
    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):  # no signature to read (some builtins): trust it
        return True
    return any(
        p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD, p.VAR_POSITIONAL) for p in params
    )


def _signature_problem(fn: Callable[..., Any], params: dict[str, Any]) -> str | None:
    """Why `fn(ctx, **params)` cannot be called, in the integrator's terms, or None."""
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):
        return None
    name = getattr(fn, "__name__", "handler")
    args = list(sig.parameters.values())
    if any(p.kind == p.VAR_KEYWORD for p in args):
        unexpected: list[str] = []
    else:
        accepted = {p.name for p in args[1:] if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}
        unexpected = [k for k in params if k not in accepted]
    if unexpected:
        return (
            f"handler {name}() does not accept parameter {', '.join(map(repr, unexpected))} sent by the server: "
            f"add it to its signature (or take **params)"
        )
    missing = [
        p.name
        for p in args[1:]
        if p.default is p.empty
        and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
        and p.name not in params
    ]
    if missing:
        return (
            f"handler {name}() needs parameter {', '.join(map(repr, missing))}, which the server did not send "
            f"(an optional parameter left unset, or not one of the skill's): give it a default, like "
            f"{missing[0]}=None"
        )
    return None


def _check_name(what: str, value: Any) -> None:
    """Names travel in key expressions and the manifest: refuse a bad one now."""
    if not isinstance(value, str) or not NAME_RE.match(value) or len(value) > 64:
        raise ValueError(
            f"{what} {value!r} must start with a letter and hold only letters, digits, '_' "
            f"and '-' (at most 64)"
        )
