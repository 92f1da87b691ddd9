"""What a handler gets: the SkillContext, a view of one Execution of the
active skill (its task, pause and stop state, barrier resources).

Handlers run on the agent's loop (coroutines) or in a worker thread (plain
functions): `progress` and `check` work from both; the coroutines
(`checkpoint`, `sleep`, `ask`, `tell`, `ask_operator`) only on the loop.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import zenoh

from backend.agent.outcomes import SkillStopped
from backend.agent.questions import Reply
from backend.agent.queue import Active, HeldSkill
from backend.agent.runtime import Runtime
from backend.core.model import Pose, Position, SkillInstance

_POSITION_KEYS = frozenset(Position.model_fields)


@dataclass
class Execution:
    """One run of the queue's active skill and everything that must be
    released when it ends."""

    active: Active  # the queue's record: entry and pause reasons
    task: asyncio.Task[None] | None = None
    aborted: bool = False  # stopped/reset: the task must not touch agent state any more
    # set while not paused; the asyncio one for coroutines, the threading one for threads
    resumed: asyncio.Event = field(default_factory=asyncio.Event)
    resumed_t: threading.Event = field(default_factory=threading.Event)
    pause_requested: asyncio.Event = field(default_factory=asyncio.Event)
    # barrier resources (withdrawn when the skill ends or is stopped)
    barrier_entities: list[Any] = field(default_factory=list)
    barrier_token: zenoh.LivelinessToken | None = None
    result_info: str = ""  # a handler's Success text, reported with `success`
    # a timeout (policies.timeout / not_after) cancels the handler calls made so
    # far: those numbered below `expired_upto` (the contexts count them in `calls`)
    calls: int = 0
    expired_upto: int = 0
    timeout_reason: str = ""  # its task was cancelled for a timeout (not a stop): why
    deadline: asyncio.TimerHandle | None = None

    def __post_init__(self) -> None:
        self.resumed.set()
        self.resumed_t.set()

    @property
    def entry(self) -> HeldSkill:
        return self.active.entry

    @property
    def paused(self) -> bool:
        return self.active.paused

    def sync_pause_flags(self) -> None:
        """The events follow the queue's pause reasons."""
        if self.paused:
            self.resumed.clear()
            self.resumed_t.clear()
            self.pause_requested.set()
        else:
            self.pause_requested.clear()
            self.resumed.set()
            self.resumed_t.set()

    def release(self, *, abort: bool) -> None:
        """Withdraw the barrier resources; `abort` also stops the handler."""
        self.disarm()
        if abort:
            self.aborted = True
            self.resumed.set()  # wake waiters so they see the stop
            self.resumed_t.set()
            self.cancel_task()
        self.release_barrier()

    def cancel_task(self) -> None:
        # not the task we run in: a handler calling `await agent.stop()` would
        # be cancelled inside stop(), before the session is closed
        task = self.task
        if task is not None and not task.done() and task is not asyncio.current_task():
            task.cancel()

    def disarm(self) -> None:
        """No timeout any more (the skill ended, or its branch runs)."""
        if self.deadline is not None:
            self.deadline.cancel()
            self.deadline = None

    def release_barrier(self) -> None:
        for entity in self.barrier_entities:
            try:
                entity.undeclare()
            except Exception:
                pass
        self.barrier_entities.clear()
        if self.barrier_token is not None:
            try:
                self.barrier_token.undeclare()
            except Exception:
                pass
            self.barrier_token = None


class SkillRunner(Protocol):
    """What a context needs of whoever runs its skill (execution.Executor)."""

    agent: Any  # the RobotAgent: ctx.agent, its time_scale, ask and tell
    rt: Runtime

    def set_progress(
        self, act: Execution, fraction: float, info: str, eta_s: float | None
    ) -> None: ...


def _coroutine_only(method: Callable[..., Any]) -> Callable[..., Any]:
    """A SkillContext coroutine called from a plain-function handler's thread
    would only make a coroutine object nobody awaits: no wait, no pause, no
    answer. Say so instead."""

    @functools.wraps(method)
    def call(self: SkillContext, *args: Any, **kwargs: Any) -> Any:
        if not self._on_loop():
            raise RuntimeError(
                f"ctx.{method.__name__}() is for coroutine handlers (async def); the handler of "
                f"{self.skill.skill} is a plain function running in a thread: use ctx.check() "
                f"between blocking steps, or make it a coroutine"
            )
        return method(self, *args, **kwargs)

    return call


class SkillContext:
    """What a handler gets as its first argument."""

    def __init__(
        self,
        host: SkillRunner,
        act: Execution,
        params: dict[str, Any],
        purpose: str = "skill",
        skill: SkillInstance | None = None,
    ):
        self.agent: Any = host.agent  # the RobotAgent
        self._host = host
        self._act = act
        self.skill: SkillInstance = skill or act.entry.skill
        self.params: dict[str, Any] = params  # the raw values as sent by the server
        self.attempt: int = act.entry.attempt
        # "skill", "recharge" (run before this skill) or "branch" (a fallback or goto run
        # in its place: then `skill` is the one run)
        self.purpose = purpose
        self._call = act.calls
        act.calls += 1

    # -- state -----------------------------------------------------------
    @property
    def stopped(self) -> bool:
        """Stopped by the operator or out of time: the handler should return."""
        return self.cancelled_because is not None

    @property
    def cancelled_because(self) -> str | None:
        """Why the handler was cancelled: "stop" (stop, reset, the agent
        stopping), "timeout" (its policies' timeout or not_after), else None."""
        if self._act.aborted:
            return "stop"
        if self._call < self._act.expired_upto:
            return "timeout"
        return None

    @property
    def paused(self) -> bool:
        return self._act.paused

    def _on_loop(self) -> bool:
        return self._host.rt.on_loop()

    # -- progress ----------------------------------------------------------
    def progress(self, fraction: float, info: str = "", eta_s: float | None = None) -> None:
        """Report progress (0..1) for telemetry; callable from handler threads.

        Raises `SkillStopped` once the skill was stopped (handy for sync loops).
        """
        if self.stopped:
            raise SkillStopped()
        fraction = min(1.0, max(0.0, float(fraction)))
        info = "" if info is None else str(info)  # it goes into telemetry, which checks its types
        eta_s = None if eta_s is None else float(eta_s)
        if self._on_loop():
            self._host.set_progress(self._act, fraction, info, eta_s)
        else:
            self._host.rt.post(self._host.set_progress, self._act, fraction, info, eta_s)

    # -- pause / stop --------------------------------------------------------
    @_coroutine_only
    async def checkpoint(self) -> None:
        """Return when not paused; raise `SkillStopped` if stopped."""
        while True:
            if self.stopped:
                raise SkillStopped()
            if not self._act.paused:
                return
            await self._act.resumed.wait()

    def check(self) -> None:
        """Synchronous checkpoint for handlers running in a thread: blocks while
        paused, raises `SkillStopped` once stopped."""
        if self._on_loop():
            # never block the event loop: an async handler must await checkpoint()
            if self.stopped:
                raise SkillStopped()
            if self._act.paused:
                self._host.rt.say_once(
                    f"check {self.skill.skill}",
                    f"the coroutine handler of {self.skill.skill} calls ctx.check(), which cannot "
                    f"wait on the event loop: it ignores the pause; use await ctx.checkpoint() or "
                    f"await ctx.sleep()",
                    level=logging.WARNING,
                )
            return
        while True:
            if self.stopped:
                raise SkillStopped()
            if self._act.resumed_t.wait(0.1):
                if self.stopped:
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
        answer: dict[str, Any] | None = await self.agent.ask(robot, topic, data)
        return answer

    @_coroutine_only
    async def tell(self, robot: str, topic: str, data: dict[str, Any] | None = None) -> bool:
        delivered: bool = await self.agent.tell(robot, topic, data)
        return delivered

    # -- the operators ------------------------------------------------------------
    @_coroutine_only
    async def ask_operator(
        self, text: str, choices: list[str], default: str, timeout: float | str
    ) -> Reply:
        """Ask the operators (docs/robots.md "Asking the operator"): `choices`
        (2 to 9), the `default` taken when no answer reaches the robot within
        `timeout` of mission time (seconds, or '5m'; divided by
        `agent.time_scale`). Returns `Reply(choice, answered, by)`: `answered`
        False when the default applied (the robot says so to the ground).
        A stop cancels the wait (the question is withdrawn); while paused it
        returns once resumed. ValueError for a question that breaks the limits."""
        question = self.agent.questions.make(self.skill.id, text, choices, default, timeout)
        reply: Reply = await self.agent.questions.ask(question, self._withdrawn_because)
        await self.checkpoint()
        return reply

    def _withdrawn_because(self) -> str:
        why = self.cancelled_because
        if why == "stop":
            return f"{self.skill.id} was stopped"
        if why == "timeout":
            return f"{self.skill.id} ran out of time ({self._act.timeout_reason})"
        return f"the handler of {self.skill.id} was cancelled"
