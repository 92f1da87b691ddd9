"""Reading a message off the wire, within the limits of `backend.core.limits`.

Every receiver of a message from another program (the server's operation,
state, registration and report queryables, command replies, robots' world
queryables, telemetry) reads it with `parse(Model, payload)`: the payload's
size, then its nesting, strings, lists and mappings are checked before the
model is built, and a message over a limit is refused like a malformed one:
a `ValidationError` (error type `limit_exceeded`) naming the field path and
the limit, echoing at most a short prefix of the value.
"""

from __future__ import annotations

from typing import Any, TypeVar

import pydantic_core
from pydantic import BaseModel, TypeAdapter, ValidationError

from backend.core.limits import LIMITS, Limits, check_tree, show_path, too_big, too_deep
from backend.protocol.messages import first_error

M = TypeVar("M", bound=BaseModel)
T = TypeVar("T")

LIMIT_EXCEEDED = "limit_exceeded"  # the error type of a refusal by a limit


def parse(model: type[M], payload: bytes | bytearray | str, limits: Limits = LIMITS) -> M:
    """The message `payload` as a `model`, or ValidationError: malformed, or
    over a limit (`is_limit`)."""
    data = _within_limits(model.__name__, payload, limits)
    if data is _NOT_JSON:
        return model.model_validate_json(payload)  # not JSON: pydantic says where
    return model.model_validate(data)


def parse_as(
    adapter: TypeAdapter[T], payload: bytes | bytearray | str, limits: Limits = LIMITS
) -> T:
    """`parse` for what is not one model (a union such as a robot's `Command`)."""
    data = _within_limits("message", payload, limits)
    if data is _NOT_JSON:
        return adapter.validate_json(payload)
    return adapter.validate_python(data)


_NOT_JSON = object()


def _within_limits(title: str, payload: bytes | bytearray | str, limits: Limits) -> Any:
    """The payload's JSON, once held to the limits (ValidationError), or
    _NOT_JSON when it is no JSON at all."""
    n = len(payload)
    if n > limits.payload:
        raise limit_error(title, (), too_big(n, limits.payload, "a message"))
    try:
        data = pydantic_core.from_json(payload, allow_inf_nan=False)
    except ValueError as e:
        if "recursion limit" in str(e):  # the reader's own bound (200 levels) is past ours
            raise limit_error(title, (), too_deep(limits.depth)) from None
        return _NOT_JSON
    found = check_tree(data, depth=limits.depth, limits=limits)
    if found is not None:
        raise limit_error(title, found.path, found.message)
    return data


def limit_error(title: str, path: tuple[str | int, ...], message: str) -> ValidationError:
    """A ValidationError for a value over a limit: its one error has the field
    path (as one readable string, e.g. `op.params.goal[2]`) and the sentence."""
    error = pydantic_core.PydanticCustomError(LIMIT_EXCEEDED, "{message}", {"message": message})
    loc = (show_path(path),) if path else ()
    return ValidationError.from_exception_data(title, [{"type": error, "loc": loc, "input": ""}])


def is_limit(e: ValidationError) -> bool:
    """Was the message refused for a limit (not for its content)?"""
    return any(err["type"] == LIMIT_EXCEEDED for err in e.errors())


def unreadable(e: ValidationError, what: str, code: str) -> tuple[str, str]:
    """(code, sentence) refusing a message that cannot be read (`what`: "the
    uplink of lru1"): `limit_exceeded` with the field's path and the limit
    first, as every limit refusal says it, else `code` (the receiver's:
    bad_request, bad_message) with the first error."""
    if is_limit(e):
        return LIMIT_EXCEEDED, f"{first_error(e)} ({what}; nothing of it was applied)"
    return code, f"{what} cannot be read ({first_error(e)}); nothing of it was applied"
