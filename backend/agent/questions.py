"""Asking the operators (docs/robots.md "Asking the operator").

A skill's handler asks a question with choices, a default and a timeout in
mission time (`ctx.ask_operator`). The question goes down the downlink like
a report (`Ask`, numbered in the same sequence and kept in the outbox until
the ground acknowledges it, so a cut link only delays it); the operator's
answer comes up the uplink as a command (`QuestionAnswer`), applied in its
order like any other. The handler awaits one of:

- the operator's answer: it goes on with that choice (the command is
  answered `applied`; one for a question no longer asked is `refused`);
- the timeout (mission seconds / `agent.time_scale`, as contingencies): it
  goes on with the default and says so (`AskEnded`, outcome `default`);
- its task cancelled (stop, reset, the skill's own timeout, the agent
  stopping): the question is withdrawn (`AskEnded`, outcome `withdrawn`)
  and the cancellation goes on.

A pause does not stop the clock: the default may apply while paused (the
handler then waits at its checkpoint as after a `ctx.sleep`).
"""

from __future__ import annotations

import asyncio
import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Literal

from pydantic import ValidationError

from backend.agent.queue import Effect
from backend.agent.runtime import Runtime, log
from backend.core.durations import duration_s
from backend.core.model import QuestionAnswer
from backend.core.ops import Ask, AskEnded
from backend.protocol.messages import first_error

ENDED_KEPT = 100  # how questions ended, kept to answer a late answer with why


@dataclass(frozen=True)
class Reply:
    """What `ctx.ask_operator` returns: the choice to go on with, and whether
    an operator gave it (False: the default, at the timeout)."""

    choice: str
    answered: bool
    by: str = ""  # who answered ('user@console'), as the ground says


@dataclass
class _Asked:
    ask: Ask
    reply: asyncio.Future[Reply]
    timer: asyncio.TimerHandle | None = None


Downlink = Callable[[Ask | AskEnded], None]  # where a question and its end go (the outbox)


def timeout_seconds(timeout: float | str) -> float:
    """A timeout as given (90, '5m'): mission seconds (ValueError for another text)."""
    if isinstance(timeout, str):
        seconds = duration_s(timeout)
        if seconds is None:
            raise ValueError(f"timeout {timeout!r} is no duration (90, '90s', '5m', '1.5h')")
        return seconds
    return float(timeout)


class Questions:
    """The questions this run of the robot asks, until each one ends."""

    def __init__(
        self,
        rt: Runtime,
        seq: Callable[[], int],
        downlink: Downlink,
        time_scale: Callable[[], float],
    ):
        self.rt = rt
        self._seq = seq  # the next downlink number (shared with reports and answers)
        self._downlink = downlink
        self._time_scale = time_scale
        self._open: dict[str, _Asked] = {}
        self._numbers = itertools.count(1)
        self.ended: dict[str, str] = {}  # ref -> how it ended (the last ENDED_KEPT)

    @property
    def asking(self) -> list[str]:
        """The refs of the questions still asked (a registration lists them)."""
        return list(self._open)

    def _scale(self) -> float:
        scale = float(self._time_scale())
        return scale if scale > 0 else 1.0

    def make(
        self, skill: str, text: str, choices: Sequence[str], default: str, timeout: float | str
    ) -> Ask:
        """The question as it goes down; ValueError naming what is wrong."""
        now = datetime.now(UTC)
        try:
            timeout_s = timeout_seconds(timeout)
            wall = timeout_s / self._scale() if timeout_s > 0 else 0.0
            return Ask(
                robot=self.rt.name,
                seq=1,  # numbered when sent: a question refused here uses no number
                ref=f"{self.rt.session_id or 'q'}-{next(self._numbers)}",
                skill=skill,
                text=text,
                choices=list(choices),
                default=default,
                timeout_s=timeout_s,
                at=now,
                due=now + timedelta(seconds=wall),
            )
        except (ValidationError, ValueError) as e:
            why = first_error(e) if isinstance(e, ValidationError) else str(e)
            raise ValueError(
                f"robot {self.rt.name}, skill {skill}: ctx.ask_operator(): {why}"
            ) from None

    async def ask(self, question: Ask, why_cancelled: Callable[[], str]) -> Reply:
        """Send the question and wait for its answer or its default; withdrawn
        (and the cancellation goes on) when the handler is cancelled."""
        loop = asyncio.get_running_loop()
        message = question.model_copy(update={"seq": self._seq()})
        asked = _Asked(message, loop.create_future())
        self._open[message.ref] = asked
        wall = (message.due - message.at).total_seconds()
        asked.timer = loop.call_later(wall, self._default, message.ref)
        self._downlink(message)
        log.info("%s: %s asks: %s", self.rt.name, message.skill, message.text)
        try:
            return await asked.reply
        except asyncio.CancelledError:
            if message.ref in self._open:
                self._end(message.ref, "withdrawn", None, why_cancelled())
            raise

    def answer(self, cmd: QuestionAnswer) -> Effect:
        """The uplink's `answer` command: the waiting handler goes on with it."""
        asked = self._open.get(cmd.ref)
        if asked is None:
            how = self.ended.get(cmd.ref, "it is not asked by this run of the robot")
            return Effect(ok=False, reason=f"question {cmd.question} is no longer asked: {how}")
        if cmd.choice not in asked.ask.choices:
            offered = ", ".join(asked.ask.choices)
            return Effect(
                ok=False, reason=f"question {cmd.question} offers {offered}, not '{cmd.choice}'"
            )
        self._close(cmd.ref, f"answered '{cmd.choice}'")
        asked.reply.set_result(Reply(cmd.choice, True, cmd.by))
        return Effect(reason=f"{asked.ask.skill} goes on with '{cmd.choice}'")

    def _default(self, ref: str) -> None:
        """The timeout came first: the default, said on the downlink."""
        asked = self._open.get(ref)
        if asked is None:
            return
        choice = asked.ask.default
        self._end(ref, "default", choice, "no answer in time")
        if not asked.reply.done():
            asked.reply.set_result(Reply(choice, False))

    def _end(
        self,
        ref: str,
        outcome: Literal["default", "withdrawn"],
        choice: str | None,
        reason: str,
    ) -> None:
        how = f"its default '{choice}' applied" if outcome == "default" else f"withdrawn ({reason})"
        self._close(ref, how)
        self._downlink(
            AskEnded(
                robot=self.rt.name,
                seq=self._seq(),
                ref=ref,
                outcome=outcome,
                choice=choice,
                reason=reason,
                at=datetime.now(UTC),
            )
        )

    def _close(self, ref: str, how: str) -> None:
        asked = self._open.pop(ref)
        if asked.timer is not None:
            asked.timer.cancel()
        self.ended[ref] = how
        while len(self.ended) > ENDED_KEPT:
            del self.ended[next(iter(self.ended))]

    def forget(self) -> None:
        """Another run of this robot took over (its handlers were aborted)."""
        for asked in self._open.values():
            if asked.timer is not None:
                asked.timer.cancel()
        self._open.clear()
