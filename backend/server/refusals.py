"""How the server refuses: a handler's `Refusal` or bad input becomes the
`ErrorReply` its requester reads (`guard`), and the refusal of an operation
the journal could not take (`JournalFailed`)."""

from __future__ import annotations

import inspect
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from backend.core.rules.engine import Refusal
from backend.protocol.messages import ErrorReply, dumps, first_error
from backend.protocol.wire import LIMIT_EXCEEDED, is_limit
from backend.server.journal import JournalError
from backend.transport import ReplyError

Handler = Callable[..., bytes | Awaitable[bytes]]


def guard(handler: Handler) -> Handler:
    """Bad input and refusals become an ErrorReply; nothing else escapes.
    The handler answers at once (bytes) or later (an awaitable)."""

    def run(*args: Any) -> bytes | Awaitable[bytes]:
        try:
            result = handler(*args)
        except (Refusal, ValidationError) as e:
            raise _error(e) from None
        return _guarded(result) if inspect.isawaitable(result) else result

    return run


async def _guarded(pending: Awaitable[bytes]) -> bytes:
    try:
        return await pending
    except (Refusal, ValidationError) as e:
        raise _error(e) from None


def _error(e: Refusal | ValidationError) -> ReplyError:
    if isinstance(e, Refusal):
        return ReplyError(dumps(ErrorReply(**e.to_dict())))
    if is_limit(e):
        return ReplyError(dumps(ErrorReply(code=LIMIT_EXCEEDED, message=first_error(e))))
    return ReplyError(
        dumps(ErrorReply(code="bad_request", message=f"malformed request: {first_error(e)}"))
    )


class JournalFailed(Refusal):
    """The journal could not take an operation's batch: refused, nothing changed.
    Never taken as a refusal of a robot's report (the robot must send it again)."""

    def __init__(self, db: Path, error: BaseException, what: str):
        why = str(error)
        if isinstance(error, JournalError):  # the file is gone: a new journal is needed
            why = why.removeprefix(f"{db} ")
        super().__init__(
            "journal_failed",
            f"the server could not write {what} to its journal {db} ({why}): "
            f"the mission was not changed; {_what_to_do(error, why)}",
        )


def _what_to_do(error: BaseException, why: str) -> str:
    if isinstance(error, JournalError):
        return (
            "save the mission (`missionctl ctl save FILE`) and restart the server "
            "with --mission FILE and a new --db"
        )
    if isinstance(error, PermissionError):  # as a read-only file
        why += " read-only"
    return next(
        (advice for words, advice in _ADVICE if any(w in why for w in words)),
        "check the disk and the file, then send it again",
    )


# what the failure's message says -> what to do (the first that fits)
_ADVICE = (
    (("locked", "busy"), "another program holds the file locked: close it, then send it again"),
    (("full",), "free disk space, then send it again"),
    (("readonly", "read-only"), "make the file writable, then send it again"),
)
