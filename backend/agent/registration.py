"""Registration: what the robot offers (its manifest and handlers, checked
when the integrator declares them, and against the library's signatures
each server sends when it accepts the robot), its presence, and
registering with each server that appears (again after every restart of
either side)."""

from __future__ import annotations

import asyncio
import inspect
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

import zenoh
from pydantic import ValidationError

from backend import transport
from backend.agent.outbox import Outbox
from backend.agent.outcomes import AlreadyConnected, RegistrationRefused
from backend.agent.queue import SkillQueue
from backend.agent.runtime import RETRY_S, Runtime, Standing, log
from backend.agent.uplink import CommandLog
from backend.core.library import VERSION_PATTERN, SkillSignature
from backend.core.model import NAME_RE
from backend.protocol.keys import Keys
from backend.protocol.messages import (
    Manifest,
    QueueEntry,
    Register,
    RegisterReply,
    dumps,
    first_error,
)
from backend.protocol.wire import parse

# refused because another run of this robot holds the name: asked again this often
TAKEN_RETRY_S = 5.0

_SEMVER = re.compile(VERSION_PATTERN)  # what a library's skill version may be
_MODULE_VERSION = re.compile(r"^\d+\.\d+\.\d+")  # as protocol.Module: a suffix like -rc1 may follow
_ENDPOINT = re.compile(r"^[a-z][a-z0-9\-]*/\S+$")  # PROTOCOL/ADDRESS, as ctl's --connect


# ---------------------------------------------------------------- what the robot offers


@dataclass(frozen=True)
class Handler:
    """A skill's registered handler."""

    fn: Callable[..., Any]
    version: str
    raw: bool

    @property
    def is_async(self) -> bool:
        return inspect.iscoroutinefunction(self.fn)


def check_name(what: str, value: Any) -> None:
    """Names travel in key expressions and the manifest: refuse a bad one now."""
    if not isinstance(value, str) or not NAME_RE.match(value) or len(value) > 64:
        raise ValueError(
            f"{what} {value!r} must start with a letter and hold only letters, digits, '_' "
            f"and '-' (at most 64)"
        )


def check_modules(robot: str, modules: Mapping[str, Any]) -> None:
    for module, version in modules.items():
        check_name(f"robot {robot}: module", module)
        if not isinstance(version, str) or not _MODULE_VERSION.match(version):
            raise ValueError(
                f"robot {robot}: module {module} version {version!r} is not SemVer (like 2.1.0)"
            )


def endpoints(robot: str, connect: list[str] | str) -> list[str]:
    """The router endpoints, checked here: Zenoh's own complaint names neither
    the robot nor the form it wants."""
    found = [connect] if isinstance(connect, str) else list(connect)
    if not found:
        raise ValueError(
            f"robot {robot}: connect lists no endpoint; give the mission server's, "
            f"like tcp/127.0.0.1:7447"
        )
    for e in found:
        if not isinstance(e, str) or not _ENDPOINT.match(e):
            raise ValueError(
                f"robot {robot}: connect endpoint {e!r} is not PROTOCOL/ADDRESS, "
                f"like tcp/127.0.0.1:7447"
            )
    return found


def add_handler(
    handlers: dict[str, Handler],
    robot: str,
    name: str,
    handler: Handler,
    *,
    started: bool,
) -> None:
    """Register `handler` for skill `name`, or say what is wrong with it."""
    check_name(f"robot {robot}: skill name", name)
    where = f"robot {robot}, skill {name}"
    fn, version = handler.fn, handler.version
    if not isinstance(version, str) or not _SEMVER.match(version):
        raise ValueError(f"{where}: version {version!r} is not SemVer (like 1.2.0)")
    if not callable(fn):
        raise TypeError(
            f"{where}: the handler must be a function or coroutine function, "
            f"not {type(fn).__name__}"
        )
    if not _takes_ctx(fn):
        raise TypeError(
            f"{where}: the handler must take the SkillContext as its first argument, "
            f"like def {getattr(fn, '__name__', 'handler')}(ctx, **params)"
        )
    if name in handlers:
        raise ValueError(
            f"{where}: a handler is registered already "
            f"({getattr(handlers[name].fn, '__name__', '?')}); register each skill once"
        )
    if started:
        raise RuntimeError(
            f"{where}: register skills before start(); the manifest was sent without it"
        )
    handlers[name] = handler


def _takes_ctx(fn: Callable[..., Any]) -> bool:
    """Can `fn` be called with the SkillContext as its first positional argument?"""
    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):  # no signature to read (some builtins): trust it
        return True
    return any(
        p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD, p.VAR_POSITIONAL) for p in params
    )


def handler_differences(robot: str, skill: str, handler: Handler, sig: SkillSignature) -> list[str]:
    """How `handler`'s signature differs from the library's `sig`, a sentence
    each naming robot, skill and parameter (none: it fits). A handler taking
    **params accepts whatever comes: nothing to compare."""
    try:
        args = list(inspect.signature(handler.fn).parameters.values())[1:]  # after the context
    except (TypeError, ValueError):
        return []
    if any(p.kind == p.VAR_KEYWORD for p in args):
        return []
    where = f"robot {robot}, skill {skill}: handler {getattr(handler.fn, '__name__', 'handler')}()"
    named = {p.name: p for p in args if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}
    out = [
        f"{where} has no parameter {name!r} ({kind} in the library): the skill fails when it "
        f"runs; add it to the signature"
        for name, kind in sig.params.items()
        if name not in named
    ]
    for name, p in named.items():
        if name not in sig.params:
            known = ", ".join(sig.params) or "none"
            out.append(
                f"{where} takes {name!r}, which is not a parameter of {skill} in the library "
                f"({known}): it never gets a value; remove it"
            )
        elif p.default is not p.empty:
            given = sig.defaults.get(name)
            library = f"the library's default is {given!r}" if given is not None else "no default"
            out.append(
                f"{where} gives {name!r} a default ({p.default!r}) it never uses: the server "
                f"always sends it ({library}); remove the default"
            )
    return out


def manifest_bytes(robot: str, manifest: Callable[[], Manifest]) -> bytes:
    """The manifest as sent; ValueError naming the robot when it cannot be."""
    try:
        return dumps(manifest())
    except ValidationError as exc:
        raise ValueError(f"robot {robot}: the manifest is not valid: {first_error(exc)}") from None
    except Exception as exc:  # properties pydantic cannot write as JSON
        raise ValueError(
            f"robot {robot}: the manifest cannot be written as JSON "
            f"(properties must be JSON values): {exc}"
        ) from None


# ---------------------------------------------------------------- presence


async def ensure_alone(rt: Runtime, session: zenoh.Session, lease_ms: int) -> None:
    """Before anything is declared: a second agent under this name would also
    answer the commands and run every skill a second time."""
    if await transport.present_tokens(session, Keys.alive(rt.name), rt.robot.request_timeout):
        raise AlreadyConnected(
            f"robot {rt.name} is already connected (another process holds its presence): stop "
            f"that one first; a killed one is gone at once, a hung one after its lease "
            f"({lease_ms} ms)"
        )


# ---------------------------------------------------------------- registering


class Registrar:
    """Registers with the server each time its presence token appears."""

    def __init__(
        self,
        rt: Runtime,
        standing: Standing,
        queue: SkillQueue,
        outbox: Outbox,
        commands: CommandLog,
        handlers: Mapping[str, Handler],
        signatures: dict[str, SkillSignature],
        manifest: Callable[[], Manifest],
        taken: Callable[[str], None],
        learned: Callable[[Mapping[str, str]], None] = lambda outcomes: None,
        asking: Callable[[], list[str]] = list,
    ):
        self.rt = rt
        self.standing = standing
        self.handlers = handlers
        # the library's signatures the server sent (the executor reads them too)
        self.signatures = signatures
        # how the handlers differ from them (said once each, in the log)
        self.handler_problems: list[str] = []
        self.queue = queue
        self.outbox = outbox
        self.commands = commands  # the uplink's processed commands (registration says how far)
        self._manifest = manifest
        self._taken = taken  # another run of this robot holds the name: stand down
        # how its finished skills ended that others wait for (a restart forgot them)
        self._learned = learned
        self._asking = asking  # the refs of the questions its skills still ask
        self.last_reply: RegisterReply | None = None
        self._refused: str | None = None  # the server's reason, while it refuses us
        self._error = ""  # why the last registration attempt got no reply
        self._warned_unanswered = False

    @property
    def registered(self) -> bool:
        return self.standing.registered

    def offline(self) -> None:
        """The agent stopped."""
        self.standing.registered = False
        self.standing.server_up = False

    def on_server(self, alive: bool) -> None:
        self.standing.server_up = alive
        # A (re)appearing server may be a new instance: always register again.
        self.standing.unregistered()
        if alive:
            self.standing.wake()

    async def wait_registered(self, timeout: float | None) -> None:
        answered = self.standing.answered
        if answered is None:
            raise self.rt.not_started()
        try:
            async with asyncio.timeout(timeout):
                await answered.wait()
        except TimeoutError:
            raise TimeoutError(
                f"robot {self.rt.name} not registered within {timeout:g} s: {self._why_not()}"
            ) from None
        if self._refused is not None and not self.standing.registered:
            raise RegistrationRefused(self._refused)

    def _why_not(self) -> str:
        if not self.standing.server_up:
            return (
                f"no mission server is up behind {', '.join(self.rt.robot.connect)} "
                f"(its presence token is missing)"
            )
        if not self.rt.in_range():
            return "the robot is out of communication range (agent.link)"
        return f"the server did not accept the registration ({self._error or 'no answer yet'})"

    async def run(self) -> None:
        """Register whenever woken and due, until the agent stops."""
        while not self.rt.closing:
            await self.standing.woken()
            if not self.standing.server_up or self.registered or not self.rt.in_range():
                continue  # the link loop / server watcher wakes us again
            try:
                await self.register_once()
            except asyncio.CancelledError:
                raise
            except transport.NoResponder:
                self._unanswered()
                self._retry_later()
            except Exception as exc:
                self._error = str(exc) or type(exc).__name__
                log.info("%s: registration failed (%s); retrying", self.rt.name, exc)
                self._retry_later()

    def _unanswered(self) -> None:
        # the server's token is there but its register queryable is not:
        # the router's access control dropped the query
        if not self._warned_unanswered:  # once, not every retry
            self._warned_unanswered = True
            log.warning(
                "%s: the server is up but %s gets no answer: does the robot account "
                "(--user) list this robot? retrying",
                self.rt.name,
                Keys.register(self.rt.name),
            )

    def _retry_later(self, seconds: float = RETRY_S) -> None:
        assert self.rt.loop is not None
        self.rt.loop.call_later(seconds, self.standing.wake)

    def _take_signatures(self, skills: Mapping[str, SkillSignature]) -> None:
        """The library as this server has it: compare the handlers with it."""
        self.signatures.clear()
        self.signatures.update(skills)
        problems = [
            problem
            for name, handler in sorted(self.handlers.items())
            if name in skills
            for problem in handler_differences(self.rt.name, name, handler, skills[name])
        ]
        for problem in problems:
            if problem not in self.handler_problems:
                log.error("%s", problem)
        self.handler_problems = problems

    async def register_once(self) -> None:
        assert self.rt.session is not None
        await self.rt.delay()
        request = Register(
            manifest=self._manifest(),
            session=self.rt.session_id,
            queue=[
                QueueEntry(id=e.id, status=e.status, skill=e.skill.skill, params=e.skill.params)
                for e in self.queue.entries()
            ],
            downlink=list(self.outbox.reports),
            last_seq=self.queue.seq,
            uplink_applied=self.commands.applied,
            sent=datetime.now(UTC) - timedelta(seconds=self.rt.delay_s()),
            asking=self._asking(),
        )
        raw = await transport.query(
            self.rt.session,
            Keys.register(self.rt.name),
            dumps(request),
            timeout=self.rt.robot.request_timeout,
        )
        reply = parse(RegisterReply, raw)
        self.last_reply = reply
        answered = self.standing.answered
        assert answered is not None
        if not reply.accepted and reply.code == "joining":
            # announced to the operators: asked again until one adds it
            log.info("%s: %s", self.rt.name, reply.reason)
            self._error = reply.reason
            self._retry_later()
            return
        if not reply.accepted:
            log.error("%s: the server refused the registration: %s", self.rt.name, reply.reason)
            self._refused = f"the mission server refused robot {self.rt.name}: {reply.reason}"
            answered.set()  # wait_registered() raises it
            if reply.code == "taken":
                self._taken(reply.reason)
                self._retry_later(TAKEN_RETRY_S)  # ours again once the other one is gone
            return  # else tried again when the server (re)appears
        self._refused = None
        self.outbox.refused.extend(reply.refused)
        for refusal in reply.refused:
            log.warning("%s: the server refused a message: %s", self.rt.name, refusal.message)
        renumbered = self.queue.continue_after(reply.last_seq, self.outbox.reports)
        if renumbered is not None:
            self.outbox.renumbered(renumbered)
        else:
            self.outbox.ack(reply.last_seq)
        self.outbox.heartbeat_s = reply.heartbeat_s
        self._take_signatures(reply.skills)
        self._learned(reply.outcomes)
        for what, ids in (
            ("returned to the plan (this robot no longer had them)", reply.missing),
            ("adopted (this robot holds them; the mission had them unsynchronized)", reply.adopted),
            ("asked back (the mission does not give them to this robot)", reply.dropped),
        ):
            if ids:
                log.warning("%s: the server %s: %s", self.rt.name, what, ", ".join(ids))
        self.standing.registered = True
        answered.set()
        self.outbox.wake()
