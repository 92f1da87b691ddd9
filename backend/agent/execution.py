"""Execution: the queue's active skill run by its handler.

A coroutine handler runs as a task on the agent's loop, a plain function in a
daemon thread. Stop and reset cancel it at once; pause holds it at its next
checkpoint. The skill's policies apply here: autonomous retries (it stays
`running` with the next attempt), a recharge first when the battery is low,
a pause while out of communication range.
"""

from __future__ import annotations

import asyncio
import inspect
import threading
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass
from typing import Any

from backend.agent.barriers import wait_for_partners
from backend.agent.choices import Choices
from backend.agent.context import Execution, SkillContext
from backend.agent.contingency import barrier_wait, guarded, past_deadline, scale, take
from backend.agent.outcomes import Failure, SkillFailed, Success
from backend.agent.precedence import Precedence
from backend.agent.queue import SkillQueue
from backend.agent.registration import Handler
from backend.agent.runtime import Runtime, log
from backend.agent.telemetry import TelemetryFeed
from backend.core.library import SkillSignature
from backend.core.model import SkillInstance, Status, Taken
from backend.core.params import typed_params


@dataclass(frozen=True)
class _Call:
    """One call of a handler, ready to go."""

    name: str  # the skill whose handler it is ("recharge" for a recharge)
    handler: Handler
    ctx: SkillContext
    params: dict[str, Any]


class Executor:
    """Starts the queue's next skill, runs its handler, ends it."""

    def __init__(
        self,
        agent: Any,
        rt: Runtime,
        queue: SkillQueue,
        telemetry: TelemetryFeed,
        handlers: Mapping[str, Handler],
        signatures: Mapping[str, SkillSignature],
        precedence: Precedence,
        choices: Choices,
    ):
        self.agent = agent  # the RobotAgent (ctx.agent)
        self.rt = rt
        self.queue = queue
        self.telemetry = telemetry
        self.handlers = handlers
        self.signatures = signatures  # the library's, from the last registration
        self.precedence = precedence  # policies.after: waits for other robots' skills
        self.choices = choices  # markers chosen on board, before the handler runs
        self.running: Execution | None = None  # the Execution of queue.active
        # the thread of the last plain-function handler, done once it returned
        self._handler_thread: asyncio.Future[None] | None = None

    # ------------------------------------------------------------ starting and ending

    def kick(self) -> None:
        """Start the next queued skill if running and idle."""
        if self.rt.session is None:
            return
        active = self.queue.next_skill()
        if active is None:
            return
        act = Execution(active)
        self.running = act
        self.telemetry.restart_progress()
        self.telemetry.update_mode()
        act.task = asyncio.get_running_loop().create_task(
            self._execute(act), name=f"{self.rt.name}-{active.entry.id}"
        )

    def abort(self) -> Execution | None:
        """Stop the running handler now (stop, reset, the agent stopping):
        cancelled, its barrier token withdrawn. The queue says what follows."""
        act = self.running
        if act is not None:
            act.release(abort=True)
            self.running = None
        return act

    def finish(
        self,
        act: Execution,
        status: Status,
        info: str,
        branch: Taken | None = None,
        go_on: bool = False,
    ) -> None:
        """The skill ended; the queue goes on with the next one in run mode
        (after a failure only when its contingency says so: `go_on`)."""
        act.release(abort=False)
        self.running = None
        self.queue.finish(status, info, branch, go_on)
        self.kick()

    # ------------------------------------------------------------ pause

    def sync_pause(self) -> None:
        """The running handler follows the queue's pause reasons."""
        if self.running is not None:
            self.running.sync_pause_flags()

    def apply_comms_policy(self) -> None:
        """policies.pause_out_of_comms: pause the running skill while out of range."""
        act = self.running
        if act is None or act.aborted or not act.entry.skill.policies.pause_out_of_comms:
            return
        if self.rt.in_range():
            changed = self.queue.resume_after_comms()
        else:
            changed = self.queue.pause_for_comms()
        if changed:
            act.sync_pause_flags()

    def set_progress(self, act: Execution, fraction: float, info: str, eta_s: float | None) -> None:
        if act is not self.running or act.aborted:
            return
        self.telemetry.progress = fraction
        self.telemetry.eta = eta_s
        if info:
            self.telemetry.info = info

    # ------------------------------------------------------------ a skill's run

    async def _execute(self, act: Execution) -> None:
        try:
            start_info = await self._before_start(act)
            if start_info is not None:
                await guarded(self, act, start_info)
        except asyncio.CancelledError:
            if act.aborted or self.rt.session is None:
                return  # stopped / agent stopping: whoever cancelled reported it
            raise
        except Exception as exc:  # a bug in the SDK itself: never leave the skill hanging
            log.exception("%s: executing %s failed", self.rt.name, act.entry.id)
            if not act.aborted and self.running is act:
                self.finish(act, Status.FAILURE, f"agent error: {type(exc).__name__}: {exc}")

    async def _before_start(self, act: Execution) -> str | None:
        """Recharge and barrier; the first running report's text, or None when
        the skill ended meanwhile."""
        entry = act.entry
        late = past_deadline(self, act)
        if late is not None and entry.skill.policies.on_timeout != "continue":
            await take(self, act, "timeout", late)
            return None
        failed = await self.precedence.wait(
            act, scale(self), lambda text: self.queue.report(entry, Status.SYNCHWAITING, text)
        )
        if failed is not None:
            await take(self, act, "failure", failed)
            return None
        failed = await self.choices.resolve(
            act,
            lambda text, chosen: self.queue.report(entry, Status.SYNCHWAITING, text, chosen=chosen),
        )
        if failed is not None:
            await take(self, act, "failure", failed)
            return None
        recharge = await self._maybe_recharge(act)
        if act.aborted:
            return None
        if recharge is not None:  # the recharge failed: the skill fails
            self.finish(act, Status.FAILURE, recharge)
            return None
        if entry.barrier is None:
            return ""
        waiting = wait_for_partners(
            self.rt,
            act,
            lambda text: self.queue.report(entry, Status.SYNCHWAITING, text),
            self.telemetry.show,
        )
        late = await barrier_wait(self, act, waiting)
        if act.aborted or late is None:
            return late
        return late or f"barrier {entry.barrier.barrier}: all partners ready"

    async def attempts(self, act: Execution, start_info: str) -> None:
        """The handler, again after each failure while retries are left."""
        entry = act.entry
        retries = entry.skill.policies.retries
        while True:
            if act.paused:
                # paused between attempts: the retry starts once resumed
                await act.resumed.wait()
                if act.aborted:
                    return
            self.queue.report(entry, Status.RUNNING, start_info)
            self.apply_comms_policy()
            reason = await self.call_handler(act)
            if act.aborted:
                return
            if reason is None:
                self.finish(act, Status.SUCCESS, act.result_info)
                return
            if not self.queue.next_attempt():
                await take(self, act, "failure", reason)
                return
            self.telemetry.progress = None
            start_info = f"retry {entry.retries_used}/{retries} after: {reason}"

    async def _maybe_recharge(self, act: Execution) -> str | None:
        """policies.recharge_below: run the `recharge` handler first when the
        battery is low. Returns a failure reason, or None."""
        threshold = act.entry.skill.policies.recharge_below
        if (
            threshold is None
            or "recharge" not in self.handlers
            or act.entry.skill.skill == "recharge"
        ):
            return None
        try:
            level = float(self.rt.robot.battery())
        except Exception:
            log.exception("%s: agent.battery() failed", self.rt.name)
            return None
        if level >= threshold:
            return None
        # Report it under the skill's own status: synchwaiting for a barrier skill
        # (it is not ready yet), running otherwise.
        status = Status.SYNCHWAITING if act.entry.barrier is not None else Status.RUNNING
        self.queue.report(
            act.entry, status, f"recharging first: battery {level:.0%} below {threshold:.0%}"
        )
        reason = await self.call_handler(act, purpose="recharge")
        if reason is not None:
            return f"recharge before the skill failed: {reason}"
        return None

    # ------------------------------------------------------------ one handler call

    async def call_handler(
        self, act: Execution, purpose: str = "skill", skill: SkillInstance | None = None
    ) -> str | None:
        """Run the handler once (of `skill` for a contingency's branch). None =
        success, else the failure reason. Cancellation (stop, timeout) propagates."""
        call = self._prepare(act, purpose, skill)
        if isinstance(call, str):
            return call
        await self._after_straggler(act)
        try:
            result = await self._invoke(call)
        except SkillFailed as exc:
            return str(exc.reason) or "skill failed"
        except asyncio.CancelledError:
            if act.aborted or act.timeout_reason or self.rt.session is None:
                raise
            # The handler cancelled itself (e.g. a SkillStopped it raised
            # without a stop): a failure, not a stop.
            return "the handler was cancelled"
        except Exception as exc:
            # a bug in the handler: the operator gets one line, the robot's log the traceback
            log.error(
                "%s: the handler of %s (%s) raised",
                self.rt.name,
                act.entry.id,
                call.name,
                exc_info=True,
            )
            return f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        return _judge(act, result, purpose)

    def _prepare(self, act: Execution, purpose: str, skill: SkillInstance | None) -> _Call | str:
        """The call, or why the handler cannot take the parameters sent."""
        run = skill or act.entry.skill
        name = "recharge" if purpose == "recharge" else run.skill
        handler = self.handlers[name]
        if purpose == "skill":
            raw_params, kinds = dict(act.entry.skill.params), act.entry.kinds
        elif purpose == "branch":  # a fallback or a goto: sent with the skill
            raw_params, kinds = dict(run.params), act.entry.branch_kinds.get(name, {})
        else:  # run by the robot itself: with the defaults the server filled in
            sig = self.signatures.get(name)
            raw_params = dict(sig.defaults) if sig is not None else {}
            kinds = sig.params if sig is not None else {}
        params = raw_params if handler.raw else typed_params(raw_params, kinds)
        ctx = SkillContext(self, act, raw_params, purpose, skill)
        mismatch = signature_problem(handler.fn, params)
        if mismatch is not None:  # else a bare TypeError from inside the call
            log.error("%s: skill %s (%s): %s", self.rt.name, act.entry.id, name, mismatch)
            return mismatch
        return _Call(name, handler, ctx, params)

    async def _after_straggler(self, act: Execution) -> None:
        """A plain-function handler that ignored a stop still runs in its
        thread: two handlers would drive the robot at once."""
        straggler = self._handler_thread
        if straggler is None or straggler.done():
            return
        log.warning(
            "%s: the handler of the stopped skill has not returned (it never calls "
            "ctx.check()); %s waits for it before starting",
            self.rt.name,
            act.entry.id,
        )
        self.set_progress(act, 0.0, "waiting for the stopped skill's handler to return", None)
        await asyncio.shield(straggler)

    async def _invoke(self, call: _Call) -> Any:
        fn, ctx, params = call.handler.fn, call.ctx, call.params
        if call.handler.is_async:
            return await fn(ctx, **params)
        result, self._handler_thread = in_daemon_thread(fn, ctx, **params)
        value = await result
        if inspect.isawaitable(value):  # a sync function returning a coroutine
            value = await value
        return value


def _judge(act: Execution, result: Any, purpose: str) -> str | None:
    """What a handler's return value says: None = success, else the reason."""
    if isinstance(result, Failure):
        return str(result.reason) or "skill failed"
    if isinstance(result, Success) and purpose == "skill":
        act.result_info = str(result.info)
    if result is False:
        return "the handler returned False"
    return None


def in_daemon_thread(
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
        if not returned.done():
            returned.set_result(None)
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


def signature_problem(fn: Callable[..., Any], params: dict[str, Any]) -> str | None:
    """Why `fn(ctx, **params)` cannot be called, in the integrator's terms, or None."""
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):
        return None
    name = getattr(fn, "__name__", "handler")
    args = list(sig.parameters.values())[1:]  # after the context
    unexpected = _unexpected(args, params)
    if unexpected:
        return (
            f"handler {name}() does not accept parameter {', '.join(map(repr, unexpected))} "
            f"sent by the server: add it to its signature (or take **params)"
        )
    missing = [
        p.name
        for p in args
        if p.default is p.empty
        and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
        and p.name not in params
    ]
    if missing:
        sent = ", ".join(params) or "none"
        return (
            f"handler {name}() needs parameter {', '.join(map(repr, missing))}, which the server "
            f"did not send: it is not a parameter of the skill in the library (sent: {sent}); "
            f"remove it from the signature"
        )
    return None


def _unexpected(args: list[inspect.Parameter], params: dict[str, Any]) -> list[str]:
    """The parameters sent that the handler has no keyword for."""
    if any(p.kind == p.VAR_KEYWORD for p in args):
        return []
    accepted = {p.name for p in args if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}
    return [k for k in params if k not in accepted]
