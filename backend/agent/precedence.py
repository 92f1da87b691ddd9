"""`after` (precedence across robots), robot to robot, without the ground.

The robot a skill waits for answers the ask `missionctl.outcome` from its
queue ('success', 'failure', its status while it holds the skill, 'unknown')
and notes who asked while the skill had not ended; when it ends, or when the
robot learns how it ended (registering after a restart: the ground says,
`RegisterReply.outcomes`), it tells each of them (`missionctl.outcome_ended`).

The waiter asks once, then sleeps until told. It asks again only when a tell
may have been missed: the partner's presence changed (it went offline, or a
restarted partner came back), the partner came back within reach (the local
link model is looked at while it is out of reach), or a slow safety poll is
due (`SAFETY_POLL_S` mission seconds). It reports `synchwaiting` saying what
it waits for, and why the partner does not answer: offline, unreachable.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Mapping
from typing import Any

from backend import transport
from backend.agent.context import Execution
from backend.agent.queue import SkillQueue
from backend.agent.runtime import Runtime, log
from backend.agent.world import Peers
from backend.core.model import Status
from backend.protocol.keys import Keys

OUTCOME_TOPIC = "missionctl.outcome"  # ask: how did skill X end? (and tell me when it does)
ENDED_TOPIC = "missionctl.outcome_ended"  # tell: skill X ended, with its status
SAFETY_POLL_S = 600.0  # mission seconds between asks while nothing woke the waiter
REACH_POLL_S = 0.1  # wall seconds between looks at the link model while out of reach
FINAL = ("success", "failure")
MAX_WATCHED = 1000  # skills noted as asked about (a partner cannot grow the table for ever)
MAX_WATCHERS = 32  # robots noted per skill


class _Waiting:
    """One wait: woken by a tell, by the partner's presence, or the safety poll."""

    def __init__(self) -> None:
        self.woken = asyncio.Event()
        self.online: bool | None = None  # the partner's presence (None: not heard yet)

    def on_alive(self, alive: bool) -> None:
        self.online = alive
        self.woken.set()


class Precedence:
    """Both sides of `after` for one robot: see the module docstring."""

    def __init__(self, rt: Runtime, queue: SkillQueue, peers: Peers):
        self.rt = rt
        self.queue = queue
        self.peers = peers
        self.watchers: dict[str, set[str]] = {}  # skill id -> robots told when it ends
        self._waits: dict[str, _Waiting] = {}  # skill awaited -> the wait for it
        self._tells: set[asyncio.Task[None]] = set()
        peers.add_handler("ask", OUTCOME_TOPIC, self.answer)
        peers.add_handler("tell", ENDED_TOPIC, self.on_ended)

    # ------------------------------------------------------------ the awaited robot

    def answer(self, data: dict[str, Any], sender: str) -> dict[str, Any]:
        sid = str(data.get("skill", ""))
        status = self.queue.outcome(sid)
        if status not in FINAL:
            self._watch(sid, sender)
        return {"status": status}  # always a dict: 'unknown' is an answer too

    def _watch(self, sid: str, robot: str) -> None:
        robots = self.watchers.get(sid)
        if robots is None and len(self.watchers) < MAX_WATCHED:
            robots = self.watchers[sid] = set()
        if robots is not None and len(robots) < MAX_WATCHERS:
            robots.add(robot)

    def on_report(self, skill_id: str, status: Status) -> None:
        """A report of this robot: a final one tells whoever asked about it."""
        if status.value in FINAL:
            self._ended(skill_id, status.value)

    def learned(self, outcomes: Mapping[str, str]) -> None:
        """How skills of this robot ended, as the ground knows it (a restarted
        robot forgot): answered from now on, and told to whoever asked."""
        for sid, status in outcomes.items():
            if sid not in self.queue.outcomes and self.queue.holds(sid) is None:
                self.queue.outcomes[sid] = Status(status)
                self._ended(sid, status)

    def _ended(self, sid: str, status: str) -> None:
        if self.rt.session is None:
            return
        for robot in sorted(self.watchers.pop(sid, ())):
            task = asyncio.get_running_loop().create_task(self._tell(robot, sid, status))
            self._tells.add(task)
            task.add_done_callback(self._tells.discard)

    async def _tell(self, robot: str, sid: str, status: str) -> None:
        try:
            told = await self.peers.tell(robot, ENDED_TOPIC, {"skill": sid, "status": status})
        except RuntimeError:  # stopped meanwhile
            return
        if not told:  # its wait asks again (presence, reach, safety poll)
            log.info("%s: could not tell %s that %s ended (%s)", self.rt.name, robot, sid, status)

    # ------------------------------------------------------------ the waiter

    def on_ended(self, data: dict[str, Any], sender: str) -> None:
        wait = self._waits.get(str(data.get("skill", "")))
        if wait is not None:
            wait.woken.set()

    async def wait(
        self, act: Execution, scale: float, report: Callable[[str], object]
    ) -> str | None:
        """policies.after: wait until the other robot's skill succeeded. None
        to start, else why its own on_failure applies (the other skill failed)."""
        entry = act.entry
        sid, robot = entry.skill.policies.after, entry.after_robot
        if sid is None or robot is None or self.rt.session is None:
            return None
        wait = self._waits[sid] = _Waiting()
        act.barrier_entities.append(  # released with the skill's barrier resources
            transport.watch_liveliness(
                self.rt.session,
                Keys.alive(robot),
                lambda _key, alive: self.rt.post(wait.on_alive, alive),
            )
        )
        try:
            return await self._until_ended(wait, sid, robot, scale, report)
        finally:
            if self._waits.get(sid) is wait:
                del self._waits[sid]

    async def _until_ended(
        self, wait: _Waiting, sid: str, robot: str, scale: float, report: Callable[[str], object]
    ) -> str | None:
        said = ""
        while True:
            wait.woken.clear()  # before asking: a tell during the ask is not lost
            status = await self._ask(wait, robot, sid)
            if status in FINAL:
                return None if status == "success" else f"after {sid}: it failed on {robot}"
            text = f"after {sid} on {robot}: {status}"
            if text != said:
                report(text)
                said = text
            await self._news(wait, robot, SAFETY_POLL_S / scale)

    async def _ask(self, wait: _Waiting, robot: str, sid: str) -> str:
        answer = await self.peers.ask(robot, OUTCOME_TOPIC, {"skill": sid})
        if isinstance(answer, dict):
            return str(answer.get("status"))
        if not self.peers.reachable(robot):
            return f"{robot} unreachable"
        # no presence token heard by the time an ask failed: it is not there
        return f"{robot} does not answer" if wait.online else f"{robot} offline"

    async def _news(self, wait: _Waiting, robot: str, safety_s: float) -> None:
        """Until woken, the partner came back within reach, or the safety poll is due."""
        loop = asyncio.get_running_loop()
        end = loop.time() + safety_s
        out_of_reach = not self.peers.reachable(robot)
        while not wait.woken.is_set() and (left := end - loop.time()) > 0:
            try:  # out of reach, the local link model is looked at every REACH_POLL_S
                await asyncio.wait_for(wait.woken.wait(), _step(left, out_of_reach))
            except TimeoutError:
                pass
            if out_of_reach and self.peers.reachable(robot):
                return


def _step(left: float, out_of_reach: bool) -> float:
    return min(left, REACH_POLL_S) if out_of_reach else left
