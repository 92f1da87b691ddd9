"""Queries, queryables, pub/sub, liveliness and link events, with asyncio bridges.

Zenoh runs every callback on its own Python thread (serially per entity). The
rules here: callbacks never block, never await, and hand data to asyncio only
through `loop.call_soon_threadsafe`. Exceptions raised by user callbacks are
logged (never silently dropped); exceptions raised by queryable handlers are
answered to the querier with `reply_err`.
"""

from __future__ import annotations

import asyncio
import inspect
import logging
import threading
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, Literal

import zenoh
from zenoh.handlers import Callback

from backend.transport.session import TransportError

log = logging.getLogger(__name__)

DEFAULT_TIMEOUT = 5.0
# Extra time we wait for Zenoh to finish a query after its own timeout fired.
_GRACE = 2.0


# ---------------------------------------------------------------- errors


class QueryFailed(TransportError):
    """A query got no usable answer."""

    def __init__(self, key: str, message: str):
        self.key = key
        super().__init__(message)


class QueryTimeout(QueryFailed):
    def __init__(self, key: str, timeout: float):
        self.timeout = timeout
        super().__init__(key, f"no answer from {key} within {timeout:g} s")


class NoResponder(QueryFailed):
    def __init__(self, key: str):
        super().__init__(key, f"nothing answers queries on {key}")


class QueryError(QueryFailed):
    """The responder answered with `reply_err`; `payload` is what it sent."""

    def __init__(self, key: str, payload: bytes):
        self.payload = payload
        self.message = payload.decode("utf-8", errors="replace")
        super().__init__(key, self.message)


class ReplyError(Exception):
    """Raise in a queryable handler to answer with `reply_err(payload)`."""

    def __init__(self, payload: bytes | str):
        self.payload = payload.encode() if isinstance(payload, str) else bytes(payload)
        super().__init__(self.payload.decode("utf-8", errors="replace"))


# ---------------------------------------------------------------- data


@dataclass(frozen=True, slots=True)
class Message:
    """A received sample, detached from Zenoh objects."""

    key: str
    payload: bytes
    kind: Literal["put", "delete"]


@dataclass(frozen=True, slots=True)
class QueryReply:
    """One reply of `query_all`; `ok` is False for a `reply_err`."""

    key: str  # "" for errors (they carry no key)
    payload: bytes
    ok: bool


@dataclass(frozen=True, slots=True)
class TransportChange:
    """A transport to another Zenoh node (usually our router) opened or closed."""

    zid: str
    whatami: str  # "router" | "peer" | "client"
    connected: bool


def _message(sample: zenoh.Sample) -> Message:
    kind: Literal["put", "delete"] = "delete" if sample.kind == zenoh.SampleKind.DELETE else "put"
    return Message(str(sample.key_expr), sample.payload.to_bytes(), kind)


def _guarded(fn: Callable[..., object], *args: Any) -> None:
    """Call a user callback from a Zenoh thread; log (don't propagate) its errors."""
    try:
        fn(*args)
    except Exception:
        log.exception("error in callback %r", fn)


def _post(loop: asyncio.AbstractEventLoop, fn: Callable[..., object], *args: Any) -> None:
    try:
        loop.call_soon_threadsafe(fn, *args)
    except RuntimeError:  # loop closed: nobody is listening any more
        log.debug("event loop closed; dropped %r", fn)


# ---------------------------------------------------------------- queries


def _from_zenoh_itself(reply: zenoh.Reply) -> bool:
    # Zenoh's own timeout error comes either from our session (no replier) or
    # from the router (replier entity id 0); a queryable's reply_err carries
    # the queryable's entity id (> 0).
    replier = reply.replier_id
    return replier is None or replier.eid == 0


class _Collector:
    """Collects replies of one `session.get` (filled in a Zenoh thread)."""

    def __init__(self, settle: Callable[[], object] | None = None) -> None:
        self.replies: list[QueryReply] = []
        self.timed_out = False
        # called after each reply (or timeout): a single responder's answer
        # need not wait for Zenoh to end the query
        self._settle = settle

    def on_reply(self, reply: zenoh.Reply) -> None:
        sample = reply.ok
        if sample is not None:
            self.replies.append(QueryReply(str(sample.key_expr), sample.payload.to_bytes(), True))
        else:
            err = reply.err
            payload = err.payload.to_bytes() if err is not None else b""
            if payload == b"Timeout" and _from_zenoh_itself(reply):
                self.timed_out = True
            else:
                self.replies.append(QueryReply("", payload, False))
        if self._settle is not None:
            self._settle()


def _start_get(
    session: zenoh.Session,
    key: str,
    payload: bytes | None,
    timeout: float,
    collector: _Collector,
    on_done: Callable[[], object],
) -> None:
    # With a Callback handler `get` returns at once; `drop` runs after the last reply.
    # indirect=False: the callbacks run on Zenoh's own thread instead of a new
    # Python thread per query (~0.3 ms each); they only record and post.
    try:
        session.get(
            key,
            Callback(collector.on_reply, on_done, indirect=False),
            payload=payload,
            timeout=timeout,
            consolidation=zenoh.ConsolidationMode.NONE,
        )
    except zenoh.ZError as exc:
        raise TransportError(f"cannot query {key}: {exc}") from exc


def _single(key: str, timeout: float, collector: _Collector) -> bytes:
    for reply in collector.replies:
        if reply.ok:
            return reply.payload
    for reply in collector.replies:
        raise QueryError(key, reply.payload)
    if collector.timed_out:
        raise QueryTimeout(key, timeout)
    raise NoResponder(key)


def _all(key: str, timeout: float, collector: _Collector) -> list[QueryReply]:
    if collector.timed_out and not collector.replies:
        raise QueryTimeout(key, timeout)
    return list(collector.replies)


async def _get_async(
    session: zenoh.Session, key: str, payload: bytes | None, timeout: float, *, single: bool = False
) -> _Collector:
    loop = asyncio.get_running_loop()
    done = loop.create_future()

    def finish() -> None:
        if not done.done():
            done.set_result(None)

    posted = False

    def post_finish() -> None:
        # once: after a single responder's reply, further replies and the
        # query's end need no wake-up of the loop (same Zenoh thread)
        nonlocal posted
        if not posted:
            posted = True
            _post(loop, finish)

    collector = _Collector(post_finish if single else None)
    _start_get(session, key, payload, timeout, collector, post_finish)
    try:
        await asyncio.wait_for(done, timeout + _GRACE)
    except TimeoutError:
        raise QueryTimeout(key, timeout) from None
    return collector


def _get_sync(
    session: zenoh.Session, key: str, payload: bytes | None, timeout: float
) -> _Collector:
    done = threading.Event()
    collector = _Collector()
    _start_get(session, key, payload, timeout, collector, done.set)
    # Event.wait stays interruptible by Ctrl-C, unlike a blocking Zenoh recv.
    if not done.wait(timeout + _GRACE):
        raise QueryTimeout(key, timeout)
    return collector


async def query(
    session: zenoh.Session, key: str, payload: bytes | None = None, timeout: float = DEFAULT_TIMEOUT
) -> bytes:
    """Ask the single responder of `key`; return the payload of its OK reply.

    Raises `QueryError` (it answered with reply_err), `QueryTimeout`, or
    `NoResponder` (no queryable matches: this fails at once).
    """
    return _single(key, timeout, await _get_async(session, key, payload, timeout, single=True))


def query_sync(
    session: zenoh.Session, key: str, payload: bytes | None = None, timeout: float = DEFAULT_TIMEOUT
) -> bytes:
    """Blocking `query`, for the CLI and threads (never call it from a Zenoh callback)."""
    return _single(key, timeout, _get_sync(session, key, payload, timeout))


async def query_all(
    session: zenoh.Session,
    key_expr: str,
    payload: bytes | None = None,
    timeout: float = DEFAULT_TIMEOUT,
) -> list[QueryReply]:
    """All replies (OK and error) from every matching queryable; [] when none exists.

    Raises `QueryTimeout` only when responders existed but none answered in time.
    """
    return _all(key_expr, timeout, await _get_async(session, key_expr, payload, timeout))


def query_all_sync(
    session: zenoh.Session,
    key_expr: str,
    payload: bytes | None = None,
    timeout: float = DEFAULT_TIMEOUT,
) -> list[QueryReply]:
    return _all(key_expr, timeout, _get_sync(session, key_expr, payload, timeout))


# ---------------------------------------------------------------- queryables


def _is_wild(key_expr: str) -> bool:
    return "*" in key_expr  # covers "*", "**" and "$*"


def _respond(query: zenoh.Query, reply_key: str, outcome: bytes | BaseException) -> None:
    """Answer and finalise a query (the querier waits until the query is dropped)."""
    with query:
        try:
            if isinstance(outcome, ReplyError):
                query.reply_err(outcome.payload)
            elif isinstance(outcome, BaseException):
                why = f"{type(outcome).__name__}: {outcome}"
                query.reply_err(f"internal error while handling {reply_key}: {why}".encode())
            else:
                query.reply(reply_key, outcome)
        except Exception:
            log.exception("cannot answer query on %s", reply_key)


def _check_bytes(result: object) -> bytes:
    if not isinstance(result, (bytes, bytearray, memoryview)):
        raise TypeError(f"queryable handler returned {type(result).__name__}, expected bytes")
    return bytes(result)


def _reply_key(queryable_key: str, query: zenoh.Query) -> str:
    # Reply on a concrete key: ours if we serve one, else the (concrete) query key.
    return str(query.key_expr) if _is_wild(queryable_key) else queryable_key


def serve(
    session: zenoh.Session, key_expr: str, handler: Callable[[bytes], bytes]
) -> zenoh.Queryable[None]:
    """Declare a queryable answering with `handler(payload)` (b"" when no payload).

    `ReplyError(payload)` -> `reply_err(payload)`; any other exception is logged
    and answered with `reply_err("internal error ...")`. The handler runs on a
    Zenoh thread and blocks this queryable while it runs: keep it short.
    """

    def on_query(query: zenoh.Query) -> None:
        payload = query.payload.to_bytes() if query.payload is not None else b""
        outcome: bytes | BaseException
        try:
            outcome = _check_bytes(handler(payload))
        except ReplyError as exc:
            outcome = exc
        except Exception as exc:
            log.exception("queryable handler for %s failed", key_expr)
            outcome = exc
        _respond(query, _reply_key(key_expr, query), outcome)

    return session.declare_queryable(key_expr, on_query)


def serve_async(
    session: zenoh.Session,
    key_expr: str,
    handler: Callable[..., bytes | Awaitable[bytes]],
    loop: asyncio.AbstractEventLoop | None = None,
    *,
    with_key: bool = False,
) -> zenoh.Queryable[None]:
    """Like `serve`, but `handler` runs on `loop`'s thread.

    The Zenoh thread only hands the query over, so all handler code runs on
    the event loop's thread. `handler` is a coroutine function, or a plain
    function returning the answer (answered in the same loop callback, no
    task) or an awaitable (run as a task, answered when it completes).
    With `with_key`, the handler gets `(payload, key)`: the query's key (for
    wildcard queryables whose key names the robot or user).
    """
    target = loop or asyncio.get_running_loop()
    tasks: set[asyncio.Task[None]] = set()  # the loop keeps only weak references to tasks

    def failed(exc: Exception) -> BaseException:
        if not isinstance(exc, ReplyError):
            log.error("queryable handler for %s failed", key_expr, exc_info=exc)
        return exc

    async def finish(query: zenoh.Query, pending: Awaitable[bytes]) -> None:
        outcome: bytes | BaseException
        try:
            outcome = _check_bytes(await pending)
        except Exception as exc:
            outcome = failed(exc)
        _respond(query, _reply_key(key_expr, query), outcome)

    def start(query: zenoh.Query, payload: bytes) -> None:
        outcome: bytes | BaseException
        try:
            result = handler(*((payload, str(query.key_expr)) if with_key else (payload,)))
            if inspect.isawaitable(result):
                task = target.create_task(finish(query, result))
                tasks.add(task)
                task.add_done_callback(tasks.discard)
                return
            outcome = _check_bytes(result)
        except Exception as exc:
            outcome = failed(exc)
        _respond(query, _reply_key(key_expr, query), outcome)

    def on_query(query: zenoh.Query) -> None:
        payload = query.payload.to_bytes() if query.payload is not None else b""
        try:
            hand_over(target, start, query, payload)
        except RuntimeError:  # loop closed
            _respond(query, _reply_key(key_expr, query), RuntimeError("service is shutting down"))

    return session.declare_queryable(key_expr, on_query)


def hand_over(loop: asyncio.AbstractEventLoop, fn: Callable[..., object], *args: Any) -> None:
    """A queryable's Zenoh thread hands a query to the event loop: one loop
    callback, no task unless the handler awaits (named for the benchmarks'
    tracing)."""
    loop.call_soon_threadsafe(fn, *args)


# ---------------------------------------------------------------- pub/sub


def declare_publisher(
    session: zenoh.Session,
    key_expr: str,
    *,
    express: bool = False,
    priority: zenoh.Priority | None = None,
) -> zenoh.Publisher:
    """A publisher that blocks rather than drops under congestion (state must not be lost)."""
    return session.declare_publisher(
        key_expr,
        congestion_control=zenoh.CongestionControl.BLOCK,
        express=express,
        priority=priority,
    )


def wait_matching(publisher: zenoh.Publisher, timeout: float) -> bool:
    """Block until some subscriber matches `publisher` (True) or `timeout` passes (False)."""
    matched = threading.Event()
    listener = publisher.declare_matching_listener(
        lambda status: matched.set() if status.matching else None
    )
    try:
        # matching_status is a MatchingStatus object, not a bool (whatever the stubs say)
        status: Any = publisher.matching_status
        if status.matching:
            return True
        return matched.wait(timeout)
    finally:
        listener.undeclare()


def undeclare(entity: Any) -> None:
    """Undeclare a subscriber (or queryable) when its session may be closed already."""
    if entity is None:
        return
    try:
        entity.undeclare()
    except Exception:  # the session is closed: so is the entity
        pass


def subscribe(
    session: zenoh.Session, key_expr: str, on_message: Callable[[Message], object]
) -> zenoh.Subscriber[None]:
    """Call `on_message(Message)` on a Zenoh thread for every sample. It must not block."""
    return session.declare_subscriber(
        key_expr, lambda sample: _guarded(on_message, _message(sample))
    )


def subscribe_on_loop(
    session: zenoh.Session,
    key_expr: str,
    on_payload: Callable[[bytes], object],
    loop: asyncio.AbstractEventLoop | None = None,
) -> zenoh.Subscriber[None]:
    """Call `on_payload(payload)` on `loop` (the running one by default) for
    every sample; dropped once the loop is closed."""
    target = loop or asyncio.get_running_loop()
    return subscribe(session, key_expr, lambda message: _post(target, on_payload, message.payload))


def subscribe_to_queue(
    session: zenoh.Session, key_expr: str, loop: asyncio.AbstractEventLoop | None = None
) -> tuple[zenoh.Subscriber[None], asyncio.Queue[Message]]:
    """Deliver samples into an (unbounded) asyncio.Queue consumed on `loop`."""
    target = loop or asyncio.get_running_loop()
    queue: asyncio.Queue[Message] = asyncio.Queue()
    subscriber = subscribe(
        session, key_expr, lambda message: _post(target, queue.put_nowait, message)
    )
    return subscriber, queue


# ---------------------------------------------------------------- presence and links


def declare_token(session: zenoh.Session, key: str) -> zenoh.LivelinessToken:
    """A liveliness token: others see it until it is undeclared, the session closes,
    the process dies (at once) or hangs (after the lease)."""
    return session.liveliness().declare_token(key)


def watch_liveliness(
    session: zenoh.Session,
    key_expr: str,
    on_change: Callable[[str, bool], object],
    *,
    history: bool = True,
) -> zenoh.Subscriber[None]:
    """Call `on_change(key, alive)` for tokens appearing/disappearing; with
    `history`, tokens that already exist are reported as alive first."""

    def on_sample(sample: zenoh.Sample) -> None:
        _guarded(on_change, str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)

    return session.liveliness().declare_subscriber(key_expr, on_sample, history=history)


async def present_tokens(session: zenoh.Session, key_expr: str, timeout: float = 2.0) -> list[str]:
    """Keys of the liveliness tokens matching `key_expr` right now (one round
    trip to the router; [] when there are none)."""
    loop = asyncio.get_running_loop()
    done = loop.create_future()
    found: list[str] = []

    def on_reply(reply: zenoh.Reply) -> None:
        if reply.ok is not None:
            found.append(str(reply.ok.key_expr))

    def finish() -> None:
        if not done.done():
            done.set_result(None)

    try:
        # a Python thread of its own (indirect): Zenoh ends a liveliness query
        # holding the session's lock, and a callback run there waits for the
        # GIL (see NOTES.md, "Deadlock"); this runs once per robot start
        session.liveliness().get(
            key_expr, Callback(on_reply, lambda: _post(loop, finish)), timeout=timeout
        )
    except zenoh.ZError as exc:
        raise TransportError(f"cannot ask for the tokens of {key_expr}: {exc}") from exc
    try:
        await asyncio.wait_for(done, timeout + _GRACE)
    except TimeoutError:
        raise QueryTimeout(key_expr, timeout) from None
    return sorted(set(found))


def transport_events(
    session: zenoh.Session,
    on_change: Callable[[TransportChange], object],
    *,
    history: bool = True,
) -> zenoh.TransportEventsListener[None]:
    """Report transports (for a client: its router link) opening and closing.

    With `history`, transports already open are reported as connected first.
    Clients reconnect by themselves after a router restart.
    """

    def on_event(event: zenoh.TransportEvent) -> None:
        transport = event.transport
        change = TransportChange(
            zid=str(transport.zid),
            whatami=str(transport.whatami).lower(),
            connected=event.kind == zenoh.SampleKind.PUT,
        )
        _guarded(on_change, change)

    return session.info.declare_transport_events_listener(on_event, history=history)
