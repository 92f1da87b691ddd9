"""Submitting operations: what a screen awaits in its own worker — no Textual here.

A screen calls `await ops.submit(op, what, ...)` from a worker (the UI never
waits on the network) and gets an `OperationOutcome`: the server's reply, its
refusal, or the failure. Saying so is done here, the same for every
screen: "… what" and then "✓ what" (or the refusal) on the status line the
screen passes (`say`), a notification for a refusal, a failure or the
reply's notes, and an entry in the event log; a refusal is also one of the
console's own alerts (its notification is the one shown already). What a
screen does with a success (select the new skill, say what was queued) it
does itself, after the await.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from backend.client.client import ClientError, OperationRefused
from backend.protocol.messages import ErrorReply, OpReply
from console.state.changes import StateChange, Topic, change
from console.state.model import ConsoleModel

Say = Callable[..., object]  # say(text, severity="info"): a screen's status line


class Backend(Protocol):
    """What the console needs to change the mission (the client, or a test double)."""

    async def submit(self, op: Any, *, expected_revision: int | None = None) -> OpReply: ...


class Notify(Protocol):
    def __call__(
        self, message: str, *, title: str = "", severity: Any = "information", timeout: float = 8
    ) -> None: ...


@dataclass(frozen=True, slots=True)
class OperationOutcome:
    """How an operation ended: `reply` when applied, else `refusal` (the
    server's, with code, robot, skill and parameter) or `failure` (a
    sentence: timeout, server gone, not connected)."""

    reply: OpReply | None = None
    refusal: ErrorReply | None = None
    failure: str = ""

    @property
    def ok(self) -> bool:
        return self.reply is not None


def refusal_text(reply: ErrorReply, robot: str | None = None, skill: str | None = None) -> str:
    """'[lru1 · lru1-3] cannot edit …': who it is about, then the server's sentence."""
    who = [x for x in (reply.robot or robot, reply.skill or skill) if x]
    head = f"[{' · '.join(who)}] " if who else ""
    return f"{head}{reply.message}"


class ReadOnlyBackend:
    """The backend of a console that never changes the mission (an observer's
    browser view): every operation is refused here, before the network."""

    def __init__(self, reason: str) -> None:
        self.reason = reason

    async def submit(self, op: Any, *, expected_revision: int | None = None) -> OpReply:
        raise ClientError(f"read-only: {self.reason}")


def _quiet(*_args: Any, **_kw: Any) -> None:
    """A status line nobody shows."""


class OperationService:
    """Submits operations to the backend and says how they ended."""

    def __init__(
        self,
        model: ConsoleModel,
        backend: Callable[[], Backend | None],
        notify: Notify,
        publish: Callable[[StateChange], None],
        whoami: Callable[[], dict[str, str]],
    ) -> None:
        self.model = model
        self._backend = backend
        self._notify = notify
        self._publish = publish
        self._whoami = whoami
        self.fallback_say: Say | None = None  # where a screen without a status line reports

    async def submit(
        self,
        op: Any,
        what: str,
        *,
        robot: str | None = None,
        skill: str | None = None,
        expected_revision: int | None = None,
        say: Say | None = None,
        done: str | None = None,
    ) -> OperationOutcome:
        """Submit `op` (`what` names it); `done`: the success's status line
        ("✓ what" if None; "" says nothing: the screen says it)."""
        say = say or self.fallback_say or _quiet
        backend = self._backend()
        if backend is None:
            self._notify("not connected to a mission server", severity="error")
            return OperationOutcome(failure="not connected to a mission server")
        say(f"… {what}")
        try:
            reply = await backend.submit(op, expected_revision=expected_revision)
        except OperationRefused as e:
            self._refused(what, say, e.reply, robot, skill)
            return OperationOutcome(refusal=e.reply)
        except ClientError as e:
            self._failed(what, say, e, robot, skill)
            return OperationOutcome(failure=str(e))
        if done is None:
            say(f"✓ {what}", "ok")
        elif done:
            say(done, "ok")
        if reply.notes:  # one toast: toasts of one title fold into the last, "(×2)"
            self._notify("\n".join(reply.notes), title=what, severity="warning", timeout=8)
        return OperationOutcome(reply=reply)

    def _refused(
        self, what: str, say: Say, reply: ErrorReply, robot: str | None, skill: str | None
    ) -> None:
        text = refusal_text(reply, robot, skill)
        say(f"✗ {what} refused: {text}", "error")
        self._notify(text, title=f"Refused: {what}", severity="error", timeout=8)
        self.refused(f"{what} refused: {text}", reply.robot or robot, reply.skill or skill)

    def refused(self, text: str, robot: str | None, skill: str | None) -> None:
        """The console's own refusal: logged, and an alert (notified already)."""
        m = self.model
        at = m.clock()
        m.log.add(
            "refusal", text, at, robots=[robot] if robot else [], skill=skill, **self._whoami()
        )
        a = m.alerts.add("refusal", text, at, robot=robot, skill=skill)
        alerts = (a,) if a is not None else ()
        self._publish(change(Topic.LOG, Topic.ALERTS, alerts=alerts, notified=True))

    def _failed(
        self, what: str, say: Say, e: ClientError, robot: str | None, skill: str | None
    ) -> None:
        say(f"✗ {what}: {e}", "error")
        self._notify(str(e), title=f"Failed: {what}", severity="error", timeout=8)
        m = self.model
        m.log.add(
            "failure",
            f"{what}: {e}",
            m.clock(),
            robots=[robot] if robot else [],
            skill=skill,
            **self._whoami(),
        )
        self._publish(change(Topic.LOG))
