"""Contingencies on board (policies timeout, not_after, on_failure,
on_timeout): what the robot does without a round trip to the ground.

Time is mission time (docs/robots.md "Contingencies"): a timeout of 10m is
ten minutes on the mission clock, i.e. 10 min / `agent.time_scale` of the
robot's wall time (the simulator's speed); `not_after` is an instant on
`agent.mission_time()`. The timeout counts from the skill's first `running`
(after a recharge and its barrier), retries and pauses included.

Branches: `halt` (the failure halts the queue, as without a contingency),
`skip` (failure, the queue goes on), `continue` (on a timeout: the skill runs
on past it; on a failure: as skip), a fallback (its skills run in place of the
failed one; the queue goes on once they succeeded) and a goto (the robot's
drive skill to a marker, then it halts there). Every branch taken is reported:
`running` with the branch when its skills start, then the final `failure`
with the branch and why.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable
from typing import Any, Literal, cast

from backend.agent.context import Execution
from backend.core.contingency import clock_text, span_text
from backend.core.model import Fallback, Goto, SkillInstance, Status, Taken

Trigger = Literal["failure", "timeout"]


def scale(ex: Any) -> float:
    """Mission seconds per robot second (the sim's speed)."""
    value = float(ex.agent.time_scale)
    return value if value > 0 else 1.0


def _now(ex: Any) -> float:
    """The mission clock (an integrator's clock that raises fails the skill)."""
    return float(ex.agent.mission_time())


def past_deadline(ex: Any, act: Execution) -> str | None:
    """Why the skill must not start (its not_after passed), or None."""
    deadline = act.entry.skill.policies.not_after
    if deadline is None or _now(ex) < deadline:
        return None
    return f"not started: past its deadline (not_after {clock_text(deadline)})"


def arm(ex: Any, act: Execution) -> None:
    """Start the skill's clock: at its timeout or deadline, `expire`."""
    pol = act.entry.skill.policies
    budgets: list[tuple[float, str]] = []
    if pol.timeout is not None:
        budgets.append((pol.timeout, f"out of time after {span_text(pol.timeout)}"))
    if pol.not_after is not None:
        budgets.append((pol.not_after - _now(ex), f"past its deadline {clock_text(pol.not_after)}"))
    if budgets:
        mission_s, why = min(budgets)
        wall = max(0.0, mission_s) / scale(ex)
        act.deadline = asyncio.get_running_loop().call_later(wall, expire, ex, act, why)


def expire(ex: Any, act: Execution, why: str) -> None:
    """The timeout or deadline came (the skill is still running: its end
    disarms it): `continue` lets it run on (said once); every other branch
    cancels the handler calls and takes it."""
    act.deadline = None
    if act.entry.skill.policies.on_timeout == "continue":
        taken = Taken(trigger="timeout", branch="continue", reason=why)
        ex.queue.report(act.entry, Status.RUNNING, f"{why}: it runs on (continue)", taken)
        return
    act.expired_upto = act.calls
    act.timeout_reason = why
    act.cancel_task()


async def guarded(ex: Any, act: Execution, start_info: str) -> None:
    """The skill's attempts under its timeout; a timeout takes on_timeout."""
    arm(ex, act)
    try:
        await ex.attempts(act, start_info)
    except asyncio.CancelledError:
        if act.aborted or not act.timeout_reason:
            raise
        cast(asyncio.Task[None], act.task).uncancel()  # ours: it goes on with its branch
        await take(ex, act, "timeout", act.timeout_reason)
    finally:
        act.disarm()


async def take(ex: Any, act: Execution, trigger: Trigger, reason: str) -> None:
    """End the skill by its contingency for `trigger` (policies.on_failure /
    on_timeout), reporting the branch and why."""
    act.disarm()
    pol = act.entry.skill.policies
    branch = pol.on_failure if trigger == "failure" else pol.on_timeout
    if isinstance(branch, Fallback | Goto):
        await _run_branch(ex, act, trigger, reason, branch)
        return
    info = f"{reason} → {branch}" if branch != "halt" else reason
    taken = Taken(trigger=trigger, branch=branch, reason=reason)
    ex.finish(act, Status.FAILURE, info, taken, go_on=branch != "halt")


async def _run_branch(
    ex: Any, act: Execution, trigger: Trigger, reason: str, branch: Fallback | Goto
) -> None:
    """Run a fallback's or a goto's skills (sent with the sync) in place of the skill."""
    kind: Literal["fallback", "goto"] = "fallback" if isinstance(branch, Fallback) else "goto"
    taken = Taken(trigger=trigger, branch=kind, reason=reason)
    skills = _branch_skills(act, trigger)
    names = ", ".join(s.skill for s in skills)
    what = f"{reason} → {kind}" + (f" to {branch.goto}" if isinstance(branch, Goto) else "")
    ex.queue.report(act.entry, Status.RUNNING, f"{what}: {names}", taken)
    failed = await _run_all(ex, act, skills)
    if act.aborted:
        return  # stopped: whoever stopped it reported it
    done = f"{what}: {failed or names + ' done'}"
    ex.finish(act, Status.FAILURE, done, taken, go_on=kind == "fallback" and not failed)


async def _run_all(ex: Any, act: Execution, skills: list[SkillInstance]) -> str:
    """Run the branch's skills in order: '' when all succeeded, else which failed and why."""
    for s in skills:
        why = await ex.call_handler(act, purpose="branch", skill=s)
        if why is not None:
            return f"{s.skill} failed too: {why}"
    return ""


def _branch_skills(act: Execution, trigger: Trigger) -> list[SkillInstance]:
    b = act.entry.branches
    if b is None:
        return []
    return b.on_failure if trigger == "failure" else b.on_timeout


async def barrier_wait(ex: Any, act: Execution, waiting: Awaitable[None]) -> str | None:
    """Wait at the skill's barrier within its timeout (BarrierInfo). '' when
    the partners came; the start text when it starts alone (on_timeout
    continue); None when it failed (halt)."""
    info = act.entry.barrier
    assert info is not None
    if info.timeout is None:
        await waiting
        return ""
    try:
        async with asyncio.timeout(info.timeout / scale(ex)):
            await waiting
        return ""
    except TimeoutError:
        why = f"barrier {info.barrier}: partners not ready after {span_text(info.timeout)}"
    taken = Taken(trigger="timeout", branch=info.on_timeout, reason=why)
    if info.on_timeout == "halt":
        ex.finish(act, Status.FAILURE, why, taken)
        return None
    started = f"{why} → continue: starting alone"
    ex.queue.report(act.entry, Status.RUNNING, started, taken)
    return started
