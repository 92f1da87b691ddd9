"""A robot's downlink on the ground: its reports and its answers to commands
share one contiguous sequence, applied strictly in order, each once, and
acknowledged cumulatively.

A message numbered past a gap is never applied before the missing ones:
the acknowledgement says what is missing (`DownlinkAck.missing`) and the
robot sends again from its last acknowledged number (its outbox keeps
everything not acknowledged). A message the rules refuse (an impossible
status change, say), or one naming another robot, is consumed all the same:
journaled as refused (`DownlinkRefused`), alerted, listed in the
acknowledgement with its seq. What a pass returns (`Progress.last_seq`) is
read back from the mission: the acknowledgement says only what the ground
applied or refused.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple, Protocol

from backend.core.alerts import AlertKind, Raises
from backend.core.ops import Answer, Ask, AskEnded, DownlinkRefused, Report
from backend.core.rules.engine import Applied, Engine, Refusal
from backend.protocol.messages import ErrorReply
from backend.server.refusals import JournalFailed

Message = Report | Answer | Ask | AskEnded  # what a downlink carries
_WHAT: dict[type, str] = {Report: "report", Answer: "answer", Ask: "question", AskEnded: "question"}


class Submitter(Raises, Protocol):
    """What the downlink needs from the server: the engine, journaled
    submission and alerts."""

    engine: Engine | None

    def submit(
        self, op: Any, *, client: str = "", request_id: str | None = None, actor: str = ""
    ) -> Applied:
        """Apply an operation: journaled, then published (JournalFailed if
        the journal cannot take it)."""
        ...


class Progress(NamedTuple):
    """What one pass over a robot's messages did."""

    last_seq: int  # applied (or refused) up to here, as the mission has it
    missing: list[int]  # [first, last] of a gap before the next message, or []
    refused: list[ErrorReply]  # each with the seq of the message it refused


def raise_alerts(host: Submitter, applied: Applied) -> None:
    """The alerts a rule raised (`Applied.alerts`)."""
    for a in applied.alerts:
        host.alert(
            a.message,
            level=a.level,
            robot=a.robot,
            skill=a.skill,
            kind=a.kind,
            command=a.command,
            question=a.question,
        )


class DownlinkApplier:
    def __init__(self, host: Submitter):
        self._host = host
        self._gaps: dict[str, int] = {}  # robot -> first missing seq already alerted

    def last_seq(self, robot: str) -> int:
        engine = self._host.engine
        assert engine is not None
        return engine.mission.report_seqs.get(robot, 0)

    def apply(self, robot: str, messages: Sequence[Message]) -> Progress:
        """Apply `robot`'s messages in seq order, up to the first gap.
        JournalFailed propagates: nothing after it is consumed, the robot
        sends it again."""
        last = self.last_seq(robot)
        refused: list[ErrorReply] = []
        for msg in sorted(messages, key=lambda m: m.seq):
            if msg.seq <= last:
                continue  # applied before: sent again
            if msg.seq != last + 1:
                self._gap(robot, last + 1, msg.seq - 1)
                return Progress(self.last_seq(robot), [last + 1, msg.seq - 1], refused)
            error = self._apply_one(robot, msg)
            if error is not None:
                refused.append(error)
            last = msg.seq
        self._gaps.pop(robot, None)
        return Progress(self.last_seq(robot), [], refused)

    def _gap(self, robot: str, first: int, upto: int) -> None:
        if self._gaps.get(robot) == first:
            return  # said once per gap
        self._gaps[robot] = first
        span = f"{first}" if first == upto else f"{first} to {upto}"
        self._host.alert(
            f"{robot} sent its downlink message {upto + 1} but not {span}: later messages "
            "wait until it sends the missing ones (nothing is skipped)",
            robot=robot,
            kind=AlertKind.ROBOT_ERROR,
        )

    def _apply_one(self, robot: str, msg: Message) -> ErrorReply | None:
        host = self._host
        try:
            if msg.robot != robot:  # its seq is this robot's: used up, never applied
                raise Refusal(
                    "bad_message",
                    f"{robot} cannot send messages of {msg.robot} (its message {msg.seq} names "
                    f"{msg.robot}); nothing of it was applied",
                    robot=robot,
                )
            applied = host.submit(msg, actor=robot)
        except JournalFailed:
            raise
        except Refusal as r:
            return self._refused(robot, msg, r)
        raise_alerts(host, applied)
        self._failed(robot, msg, applied)
        return None

    def _refused(self, robot: str, msg: Message, r: Refusal) -> ErrorReply:
        """A message refused: journaled as such, alerted, and its error for the robot."""
        host = self._host
        host.submit(
            DownlinkRefused(robot=robot, seq=msg.seq, code=r.code, message=r.message),
            actor=robot,
        )
        what = _WHAT.get(type(msg), "message")
        host.alert(
            f"{what} {msg.seq} of {robot} refused: {r.message}",
            level="error",
            robot=robot,
            skill=msg.id if isinstance(msg, Report) else None,
            kind=AlertKind.REPORT_REFUSED,
        )
        return ErrorReply(**r.to_dict(), seq=msg.seq)

    def _failed(self, robot: str, msg: Message, applied: Applied) -> None:
        """A report that a skill failed (not a duplicate): the operator is told."""
        if not isinstance(msg, Report) or applied.duplicate or msg.status.value != "failure":
            return
        self._host.alert(
            f"{robot}: {msg.id} failed: {msg.info}",
            level="error",
            robot=robot,
            skill=msg.id,
            kind=AlertKind.FAILURE,
        )
