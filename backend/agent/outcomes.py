"""How a handler ends a skill (Success, Failure, SkillFailed, SkillStopped)
and the errors the agent raises to its integrator."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass


class SkillFailed(Exception):
    """Raise in a handler to end the skill with `failure` and this reason."""

    def __init__(self, reason: str = "skill failed"):
        self.reason = reason
        super().__init__(reason)


class AlreadyConnected(RuntimeError):
    """`start()`: another agent holds this robot's presence (a second process
    of the same robot would execute every skill twice)."""


class RegistrationRefused(RuntimeError):
    """`wait_registered()`: the server refused this robot (the message says why)."""


class SkillStopped(asyncio.CancelledError):
    """Raised by `ctx.check()` / `ctx.checkpoint()` once the skill was stopped.

    A CancelledError (a BaseException), so `except Exception` in a handler
    does not swallow it: a stop always ends the handler.
    """


@dataclass(frozen=True)
class Success:
    """Return `Success("what came out")` from a handler: success, with a result
    text the operator sees as the skill's status information."""

    info: str = ""


@dataclass(frozen=True)
class Failure:
    """Return `Failure("reason")` from a handler instead of raising SkillFailed."""

    reason: str = "skill failed"
