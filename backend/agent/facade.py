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

What the agent does (the contract is docs/protocol.md, protocol 2):

- holds the liveliness token `Keys.alive(name, session)` (a fresh session
  per start), takes commands on `Keys.uplink(name)` and robot-to-robot world
  messages on `Keys.world(name)`, publishes `Telemetry` when it changes
  (deadbands, at most `telemetry_hz` a second, at least every 5 s: telemetry.py);
- watches the server's token and registers (`Register`: manifest, session,
  its queue, its unacknowledged downlink) each time the server appears, or
  when the server no longer knows it; refused because another run of this
  robot holds the name, it stands down (holds and runs nothing);
- applies each command of its uplink once, in order, never past its expiry,
  and answers what it actually did (`Answer`);
- keeps its synchronized queue itself and executes it with the registered
  handlers; every status change is a numbered `Report`; reports and answers
  share one sequence in an outbox (the downlink) until the server
  acknowledges them;
- meets its partners at barriers directly through liveliness tokens.

Parameters reach handlers typed by their kind, which the server sends with
the values (`Enqueue.kinds`, the library's; the agent holds no library): a
`pose` becomes a `Pose`, a `position` a `Position`, an `area` a
`list[Position]`; everything else (marker/robot/str/enum as str, numbers,
lists, dicts) is passed as it came, and a parameter left unset is None.
Nothing is guessed from a value's shape. Register a skill with `raw=True` to
get the values as sent, and use `ctx.params` / `ctx.pose(name)` /
`ctx.position(name)`.

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
- Reports and answers are numbered from 1 per agent run, or after the
  server's `RegisterReply.last_seq` when that is higher (a restarted robot).
- `link.delay_s` (a simulator's model of a distant robot) delays each
  command's processing, each downlink message and each telemetry sample by
  that one-way delay; an answer therefore reaches the ground two delays after
  its command left.

Threading: every state change runs on the asyncio loop that called `start()`.
Zenoh callbacks only post to that loop. Synchronous handlers run in a daemon
worker thread (so a handler that ignores stop cannot hang interpreter exit);
they may call `ctx.progress()` and `ctx.check()` (blocks while paused, raises
`SkillStopped` once stopped). World ask/tell handlers run on the loop.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import zenoh

from backend import transport
from backend.agent.choices import Choices, ChooseHook
from backend.agent.execution import Executor
from backend.agent.link import Link
from backend.agent.outbox import Outbox
from backend.agent.precedence import Precedence
from backend.agent.questions import Questions
from backend.agent.queue import Effect, SkillQueue
from backend.agent.registration import (
    Handler,
    Registrar,
    add_handler,
    check_modules,
    check_name,
    endpoints,
    ensure_alone,
    manifest_bytes,
)
from backend.agent.runtime import Runtime, Standing, log
from backend.agent.telemetry import TelemetryFeed, TelemetryPolicy
from backend.agent.uplink import CommandLog, UplinkHandler
from backend.agent.world import Peers
from backend.core.library import SkillSignature
from backend.core.model import (
    Dequeue,
    Enqueue,
    Pause,
    Pose,
    QuestionAnswer,
    Reset,
    Run,
    Status,
    Stop,
)
from backend.core.ops import Answer, Ask, AskEnded, Report
from backend.protocol.keys import Keys
from backend.protocol.messages import (
    ErrorReply,
    Manifest,
    Module,
    RegisterReply,
    Telemetry,
)
from backend.transport import timeouts
from backend.transport.login import Login

# How often the link model is polled (it is a plain callable of the integrator).
_LINK_POLL_S = 0.05


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
        link_delay_hint: float | None = None,
        telemetry: TelemetryPolicy | None = None,
    ):
        check_name("robot name", name)
        check_name(f"robot {name}: type", robot_type)
        self.name = name
        self.robot_type = robot_type
        self.connect = endpoints(name, connect)
        self.modules = dict(modules or {})
        check_modules(name, self.modules)
        self.properties = dict(properties or {})
        # the long link's expected one-way delay (s; default: the login's): the
        # lease, Zenoh's timeouts and the queries' timeouts follow from it
        login = login or Login()
        if link_delay_hint is not None:
            login = replace(login, link_delay_hint=link_delay_hint)
        self.link_delay_hint = login.link_delay_hint
        self.lease_ms = timeouts.robot_lease_ms(lease_ms, self.link_delay_hint)
        # an account (robot role) and TLS files: see docs/security.md; the lease is ours
        connection = login.zenoh_options()
        connection.pop("transport/link/tx/lease", None)
        self.zenoh_extra = {**(zenoh_extra or {}), **connection}
        self.telemetry_hz = telemetry_hz
        self.request_timeout = timeouts.query_timeout(request_timeout, self.link_delay_hint)

        # integrator-settable sources and models
        self.pose: Callable[[], Pose] = Pose
        self.battery: Callable[[], float] = lambda: 1.0
        self.link = Link()
        self.time_scale = 1.0
        # the mission clock, in seconds (policies.not_after): the simulator's when one
        # runs (it sets this), else POSIX time
        self.mission_time: Callable[[], float] = time.time
        # called with every Report as it is made (simulator, logs, tests)
        self.report_listeners: list[Callable[[Report], object]] = []
        # called with every question (Ask) and its end (AskEnded) as it is made
        self.question_listeners: list[Callable[[Ask | AskEnded], object]] = []

        # the parts, each built after what it uses (every state change runs on
        # the loop that called start())
        self._rt = Runtime(self)
        self._standing = Standing(name)
        self._queue = SkillQueue(name, on_report=self._on_report)
        # an expired command's reason says the mission clock (the sim's, once it sets it)
        self._command_log = CommandLog(
            name, lambda: self.mission_time(), lambda: float(self.time_scale)
        )
        self._outbox = Outbox(self._rt, self._standing, self._command_log)
        self._handlers: dict[str, Handler] = {}
        self._signatures: dict[str, SkillSignature] = {}  # the library's, from registration
        self._uplink = UplinkHandler(
            self._rt, self._command_log, self._dispatch, self._queue.next_seq, self._outbox
        )
        # the operators' questions of its skills (ctx.ask_operator), answered on the uplink
        self.questions = Questions(
            self._rt, self._queue.next_seq, self._on_question, lambda: self.time_scale
        )
        # telemetry_hz caps the rate; the policy says what is worth a sample
        self._telemetry = TelemetryFeed(self._rt, self._queue, telemetry)
        self._peers = Peers(self._rt)
        # other robots ask how a skill ended before starting one after it (policies.after)
        self._precedence = Precedence(self._rt, self._queue, self._peers)
        self._registrar = Registrar(
            self._rt,
            self._standing,
            self._queue,
            self._outbox,
            self._command_log,
            self._handlers,
            self._signatures,
            self.manifest,
            taken=self._stand_down,
            learned=self._precedence.learned,
            asking=lambda: self.questions.asking,
        )
        # markers chosen on board: asked of partners, or of the integrator's hook
        self._choices = Choices(self._rt, self._peers, lambda: float(self.time_scale) or 1.0)
        self._executor = Executor(
            self,
            self._rt,
            self._queue,
            self._telemetry,
            self._handlers,
            self._signatures,
            self._precedence,
            self._choices,
        )
        self.world_stats = self._peers.stats
        self._commands: dict[type, Callable[[Any], Effect]] = {
            Enqueue: self._enqueue,
            Dequeue: self._dequeue,
            Run: self._run,
            Pause: self._pause,
            Stop: self._stop,
            Reset: self._reset,
            QuestionAnswer: self.questions.answer,
        }

        # connection state
        self._entities: list[Any] = []
        self._token: zenoh.LivelinessToken | None = None  # our presence
        self._tasks: list[asyncio.Task[None]] = []
        self._in_range = True
        # what is wrong with the manifest is said now, not by a registration retried forever
        manifest_bytes(self.name, self.manifest)

    # ------------------------------------------------------------ registration API

    def skill(
        self, name: str, version: str = "1.0.0", *, raw: bool = False
    ) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
        """Decorator: `@agent.skill("drive_to", version="1.0.0")` registers a handler
        `handler(ctx, **params)` (function or coroutine). `raw=True` passes the
        parameter values unconverted."""
        if not isinstance(name, str):  # `@agent.skill` without (): would register nothing
            raise TypeError(
                f'robot {self.name}: write @agent.skill("NAME", version="1.0.0"), with the '
                f"skill's name, above {getattr(name, '__name__', name)!r}"
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
        started = self._rt.session is not None
        add_handler(self._handlers, self.name, name, Handler(fn, version, raw), started=started)

    def on_ask(self, topic: str, fn: Callable[..., Any]) -> None:
        """`fn(data, sender) -> dict | None` (or a coroutine) answers asks on
        `topic`; None means "unknown". Runs on the agent's loop: keep it short."""
        self._peers.add_handler("ask", topic, fn)

    def on_tell(self, topic: str, fn: Callable[..., Any]) -> None:
        """`fn(data, sender)` (or a coroutine) receives tells on `topic`."""
        self._peers.add_handler("tell", topic, fn)

    def on_choose(self, fn: ChooseHook) -> ChooseHook:
        """Register the hook that chooses the place of a marker chosen on board:
        `fn(choice: Choice) -> Pose | None` (or a coroutine); None while it
        does not know enough yet (asked again), SkillFailed to give up. Usable
        as a decorator. docs/robots.md "Places chosen on board"."""
        if not callable(fn):
            raise TypeError(
                f"robot {self.name}: on_choose takes a function fn(choice) -> Pose | None, "
                f"not {type(fn).__name__}"
            )
        if self._choices.hook is not None:
            raise ValueError(f"robot {self.name}: a choice hook is registered already")
        self._choices.hook = fn
        return fn

    @property
    def chosen(self) -> dict[str, Pose]:
        """Marker -> the place this robot holds for it (its choice or a partner's)."""
        return dict(self._choices.places)

    def manifest(self) -> Manifest:
        return Manifest(
            name=self.name,
            type=self.robot_type,
            modules=[Module(name=k, version=v) for k, v in self.modules.items()],
            properties=self.properties,
            skills={k: h.version for k, h in self._handlers.items()},
        )

    # ------------------------------------------------------------ introspection

    @property
    def queue(self) -> list[str]:
        """Ids of the queued (not started) skills, in order."""
        return self._queue.waiting

    @property
    def active(self) -> tuple[str, Status] | None:
        """(id, status) of the active skill, if any."""
        active = self._queue.active
        if active is None:
            return None
        return active.entry.id, active.entry.status

    @property
    def pending_reports(self) -> list[Report | Answer | Ask | AskEnded]:
        """Downlink messages (reports, answers, questions) not acknowledged by the server yet."""
        return list(self._outbox.reports)

    @property
    def session_id(self) -> str:
        """This run of the agent ('' before start())."""
        return self._rt.session_id

    @property
    def uplink_applied(self) -> int:
        """The last uplink sequence number processed (each command once)."""
        return self._uplink.log.applied

    @property
    def refused_reports(self) -> list[ErrorReply]:
        """The server's refusals of reports (its reasons)."""
        return self._outbox.refused

    @property
    def registered(self) -> bool:
        return self._registrar.registered

    @property
    def handler_problems(self) -> list[str]:
        """How the handlers differ from the library's signatures the server sent
        at the last registration (each said once in the log): a sentence each
        naming robot, skill and parameter; empty when they fit."""
        return list(self._registrar.handler_problems)

    @property
    def last_register_reply(self) -> RegisterReply | None:
        return self._registrar.last_reply

    @property
    def _session(self) -> zenoh.Session | None:
        """The Zenoh session while started (tests close it if a test forgot to)."""
        return self._rt.session

    def telemetry(self) -> Telemetry:
        return self._telemetry.snapshot()

    async def wait_acknowledged(self, timeout: float | None = None) -> None:
        """Return once the server acknowledged every report made so far
        (TimeoutError after `timeout` seconds)."""
        await self._outbox.wait_acknowledged(timeout)

    async def wait_registered(self, timeout: float | None = None) -> None:
        """Return once the current server accepted our registration.

        Raises `RegistrationRefused` (the server's reason: not in the mission,
        another type, protocol) and `TimeoutError` after `timeout` seconds,
        both with a message saying why."""
        await self._registrar.wait_registered(timeout)

    # ------------------------------------------------------------ world

    async def ask(
        self, robot: str, topic: str, data: dict[str, Any] | None = None
    ) -> dict[str, Any] | None:
        """Ask `robot` about `topic`; its answer, or None (unknown / unreachable)."""
        return await self._peers.ask(robot, topic, data)

    async def tell(self, robot: str, topic: str, data: dict[str, Any] | None = None) -> bool:
        """Tell `robot` something; True when it was delivered to a handler."""
        return await self._peers.tell(robot, topic, data)

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
        if self._rt.session is not None:
            raise RuntimeError(f"agent {self.name} is already started")
        manifest_bytes(self.name, self.manifest)  # properties may have changed since
        self._rt.attach()
        self._standing.attach()
        self._outbox.attach()
        self._uplink.attach()
        self._in_range = self._rt.in_range()
        config = transport.client_config(
            self.connect, lease_ms=self.lease_ms, extra=self.zenoh_extra
        )
        session = transport.open_session(config, what=f"the router (for robot {self.name})")
        self._rt.session = session
        try:
            await ensure_alone(self._rt, session, self.lease_ms)
            self._declare(session)
        except BaseException:
            await self.stop()
            raise

    def _declare(self, session: zenoh.Session) -> None:
        # Queryables first: once the server sees our token, commands must work.
        self._entities.append(
            transport.serve_async(session, Keys.uplink(self.name), self._uplink.on_uplink)
        )
        self._entities.append(
            transport.serve_async(session, Keys.world(self.name), self._peers.on_message)
        )
        self._telemetry.publisher = transport.declare_publisher(session, Keys.telemetry(self.name))
        self._token = transport.declare_token(session, Keys.alive(self.name, self._rt.session_id))
        self._tasks = [
            asyncio.create_task(self._registrar.run(), name=f"{self.name}-register"),
            asyncio.create_task(self._outbox.run(), name=f"{self.name}-downlink"),
            asyncio.create_task(self._uplink.run(), name=f"{self.name}-uplink"),
            asyncio.create_task(
                self._telemetry.run(self.telemetry_hz), name=f"{self.name}-telemetry"
            ),
            asyncio.create_task(self._link_loop(), name=f"{self.name}-link"),
        ]
        self._entities.append(
            transport.transport_events(
                session, lambda change: self._rt.post(self._on_router_link, change), history=False
            )
        )
        # Last: this may (re)register at once.
        self._entities.append(
            transport.watch_liveliness(
                session,
                Keys.SERVER_ALIVE,
                lambda _key, alive: self._rt.post(self._registrar.on_server, alive),
            )
        )

    async def stop(self) -> None:
        """Stop executing, try to deliver pending reports briefly, close the session.

        Safe to call twice. No report is made for a skill interrupted here: the
        robot simply goes offline (the server sees its token vanish).
        """
        session = self._rt.session
        if session is None:
            return
        tasks = list(self._tasks)
        act = self._executor.abort()
        self._queue.abandon()
        if act is not None and act.task is not None and act.task is not asyncio.current_task():
            tasks.append(act.task)
        # The flag and the wake-ups end our loops even if a cancellation gets
        # lost (Python 3.11's wait_for swallows one that races a completion).
        self._rt.closing = True
        self._standing.wake()
        self._outbox.wake()
        await self._cancel(tasks)
        self._tasks = []
        await self._outbox.flush_before_stop()
        self._rt.session = None
        self._registrar.offline()
        self._entities.clear()
        self._token = None
        self._telemetry.publisher = None
        # Closing undeclares every entity and token; without it the process
        # would hang at exit (callback subscribers keep it alive).
        transport.close_session(session)

    async def _cancel(self, tasks: list[asyncio.Task[None]]) -> None:
        for task in tasks:
            task.cancel()
        if not tasks:
            return
        _done, pending = await asyncio.wait(tasks, timeout=2.0)
        if pending:
            log.warning(
                "%s: tasks still running at stop: %s",
                self.name,
                [t.get_name() for t in pending],
            )

    # ------------------------------------------------------------ links

    def _on_router_link(self, change: transport.TransportChange) -> None:
        # Zenoh reconnects by itself; the server's token then reappears and we
        # register again. Logged because commands fail meanwhile.
        if change.connected:
            log.info("%s: connected to %s %s", self.name, change.whatami, change.zid)
        else:
            log.warning(
                "%s: lost the link to %s %s; reconnecting", self.name, change.whatami, change.zid
            )

    async def _link_loop(self) -> None:
        """Poll the link model; act on range changes."""
        while not self._rt.closing:
            await asyncio.sleep(_LINK_POLL_S)
            now = self._rt.in_range()
            if now == self._in_range:
                continue
            self._in_range = now
            log.info("%s: %s communication range", self.name, "back in" if now else "out of")
            self._executor.apply_comms_policy()
            if now:
                self._standing.wake()
                self._outbox.wake()
                self._telemetry.publish()

    # ------------------------------------------------------------ reports

    def _on_report(self, report: Report) -> None:
        """Every status change the queue makes: outbox, listeners, telemetry."""
        self._outbox.add(report)
        self._precedence.on_report(report.id, report.status)
        self._telemetry.info = report.info
        self._telemetry.update_mode()
        for listener in list(self.report_listeners):
            try:
                listener(report)
            except Exception:
                log.exception("%s: report listener failed", self.name)
        self._telemetry.publish()
        self._outbox.wake()

    def _on_question(self, message: Ask | AskEnded) -> None:
        """A question or its end: the outbox, then the listeners."""
        self._outbox.add(message)
        for listener in list(self.question_listeners):
            try:
                listener(message)
            except Exception:
                log.exception("%s: question listener failed", self.name)

    # ------------------------------------------------------------ commands

    def _dispatch(self, cmd: object) -> Effect:
        """Apply one command of the uplink to the queue and the execution.
        Synchronous: no other command or skill step interleaves, and the
        reports it makes come before its answer."""
        change = self._commands[type(cmd)](cmd)
        self._telemetry.update_mode()
        self._telemetry.publish()
        return change

    def _stand_down(self, reason: str) -> None:
        """Another run of this robot holds its name: hold and run nothing."""
        log.error("%s: standing down: %s", self.name, reason)
        self._executor.abort()
        self._queue.forget()
        self.questions.forget()
        self._outbox.clear()
        self._uplink.forget()
        self._telemetry.update_mode()

    def _enqueue(self, cmd: Enqueue) -> Effect:
        change = self._queue.enqueue(
            cmd.skills,
            cmd.barriers,
            front=cmd.front,
            offered=self._handlers,
            kinds=cmd.kinds,
            contingencies=cmd.contingencies,
            after=cmd.after,
            choose=cmd.choose,
        )
        if change.ok:
            self._executor.kick()
        return change

    def _dequeue(self, cmd: Dequeue) -> Effect:
        return self._queue.unsync(cmd.ids)

    def _run(self, cmd: Run) -> Effect:
        change = self._queue.run()
        self._executor.sync_pause()
        self._executor.kick()
        return change

    def _pause(self, cmd: Pause) -> Effect:
        change = self._queue.pause()
        self._executor.sync_pause()
        return change

    def _stop(self, cmd: Stop) -> Effect:
        self._executor.abort()
        return self._queue.stop()

    def _reset(self, cmd: Reset) -> Effect:
        self._executor.abort()
        return self._queue.reset()
