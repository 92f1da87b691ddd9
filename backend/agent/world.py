"""Robot-to-robot messages: ask a partner something (it answers or says it does
not know) or tell it something, directly over `Keys.world(robot)`, without the
server. Counted in `agent.world_stats`."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any, Literal

from pydantic import ValidationError

from backend import transport
from backend.agent.runtime import Runtime, log
from backend.protocol.keys import Keys
from backend.protocol.messages import ErrorReply, WorldMessage, WorldReply, dumps
from backend.protocol.wire import parse, unreadable


class Peers:
    """This robot's ask/tell handlers, its queries to others, and the counts."""

    def __init__(self, rt: Runtime):
        self.rt = rt
        self._handlers: dict[str, dict[str, Callable[..., Any]]] = {"ask": {}, "tell": {}}
        # asks/tells that got no answer (unknown robot, out of reach, timeout) count as failed
        self.stats = {
            "asks_sent": 0,
            "tells_sent": 0,
            "asks_failed": 0,
            "tells_failed": 0,
            "asks_received": 0,
            "tells_received": 0,
        }

    def add_handler(self, kind: Literal["ask", "tell"], topic: str, fn: Callable[..., Any]) -> None:
        where = f"robot {self.rt.name}, on_{kind} {topic!r}"
        if not callable(fn):
            raise TypeError(
                f"{where}: the handler must be a function fn(data, sender), not {type(fn).__name__}"
            )
        table = self._handlers[kind]
        if topic in table:
            raise ValueError(f"{where}: a handler is registered already; register each topic once")
        table[topic] = fn

    # ------------------------------------------------------------ answering

    async def on_message(self, payload: bytes) -> bytes:
        """The queryable on `Keys.world(name)`: an ask or a tell from a partner."""
        try:
            msg = parse(WorldMessage, payload)
        except ValidationError as e:
            code, text = unreadable(e, f"a world message to {self.rt.name}", "bad_request")
            error = ErrorReply(code=code, message=text, robot=self.rt.name)
            raise transport.ReplyError(dumps(error)) from None
        self.stats[f"{msg.kind}s_received"] += 1
        fn = self._handlers[msg.kind].get(msg.topic)
        if msg.kind == "tell":
            if fn is not None:
                await self._call("on_tell", fn, msg)
            return dumps(WorldReply(known=fn is not None))
        data = await self._call("on_ask", fn, msg) if fn is not None else None
        if data is None:
            return dumps(WorldReply(known=False))
        if not isinstance(data, dict):
            raise self._refusal(
                msg,
                f"its on_ask handler returned a {type(data).__name__}; "
                f"it must return a dict or None",
            )
        return dumps(WorldReply(known=True, data=data))

    async def _call(self, kind: str, fn: Callable[..., Any], msg: WorldMessage) -> Any:
        try:
            value = fn(msg.data, msg.sender)
            return await value if inspect.isawaitable(value) else value
        except Exception as exc:
            raise self._refusal(
                msg, f"its {kind} handler raised {type(exc).__name__}: {exc}", trace=True
            ) from None

    def _refusal(
        self, msg: WorldMessage, problem: str, trace: bool = False
    ) -> transport.ReplyError:
        """Logged here; the asker's `ask`/`tell` fails (None/False) and its log says why."""
        name = self.rt.name
        text = f"{name} cannot answer {msg.kind} {msg.topic!r} from {msg.sender}: {problem}"
        log.error("%s", text, exc_info=trace)
        return transport.ReplyError(dumps(ErrorReply(code="robot_error", message=text, robot=name)))

    # ------------------------------------------------------------ asking

    async def ask(
        self, robot: str, topic: str, data: dict[str, Any] | None = None
    ) -> dict[str, Any] | None:
        self.stats["asks_sent"] += 1
        reply = await self._query(robot, "ask", topic, data)
        if reply is None:
            self.stats["asks_failed"] += 1
        return reply.data if reply is not None and reply.known else None

    async def tell(self, robot: str, topic: str, data: dict[str, Any] | None = None) -> bool:
        self.stats["tells_sent"] += 1
        reply = await self._query(robot, "tell", topic, data)
        if reply is None:
            self.stats["tells_failed"] += 1
        return reply is not None and reply.known

    def reachable(self, robot: str) -> bool:
        """What the link model says (a model that fails counts as reachable)."""
        link = self.rt.robot.link
        try:
            return bool(link.can_reach(robot)) if hasattr(link, "can_reach") else True
        except Exception:
            log.exception("%s: link.can_reach(%s) failed; assuming reachable", self.rt.name, robot)
            return True

    async def _query(
        self, robot: str, kind: Literal["ask", "tell"], topic: str, data: dict[str, Any] | None
    ) -> WorldReply | None:
        if self.rt.session is None:
            raise self.rt.not_started()
        name = self.rt.name
        msg = WorldMessage(kind=kind, sender=name, topic=topic, data=dict(data or {}))
        if not self.reachable(robot):
            log.info("%s: %s %s/%s not sent: %s is out of reach", name, kind, robot, topic, robot)
            return None
        try:
            raw = await transport.query(
                self.rt.session,
                Keys.world(robot),
                dumps(msg),
                timeout=self.rt.robot.request_timeout,
            )
            return parse(WorldReply, raw)  # a partner's answer: held to the limits too
        except (transport.QueryFailed, transport.TransportError, ValidationError) as exc:
            log.info("%s: %s %s/%s failed: %s", name, kind, robot, topic, _why(exc))
            return None


def _why(exc: Exception) -> str:
    """A failed query in words: a robot's refusal is said by its own sentence."""
    if isinstance(exc, transport.QueryError):
        try:
            return parse(ErrorReply, exc.payload).message
        except ValidationError:
            pass
    return str(exc)
