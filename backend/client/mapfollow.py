"""Following the map feed from a client session (consoles, scripts, benchmarks).

    feed = MapFeed(session, on_update)
    await feed.start()          # subscribes to the deltas, then queries the snapshot
    feed.mirror.layers["terrain"]
    feed.close()

The same late-join rule as the mission state: subscribe first, then query
the snapshot, then apply the deltas that follow it. A gap in `seq`, or a
delta of another feed run (the simulator restarted), queries the snapshot
again; deltas arriving meanwhile are kept and applied after it. Nobody
answering the snapshot query is normal (no simulator running): the state is
then "none", and the query is repeated every `retry` seconds (an idle
simulator publishes no deltas) or as soon as a delta arrives.

Zenoh callbacks only parse and hand over to the asyncio loop; the mirror is
changed, and `on_update` called, on the loop only.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

from pydantic import ValidationError

from backend.protocol.mapfeed import (
    KEY_MAP_DELTA,
    KEY_MAP_SNAPSHOT,
    MapDelta,
    MapMirror,
    MapSnapshot,
)
from backend.transport import NoResponder, QueryFailed, QueryTimeout, query, subscribe

log = logging.getLogger(__name__)

WAITING, LIVE, NONE = "waiting", "live", "none"
RETRY_S = 2.0


@dataclass
class MapUpdate:
    """What changed in the mirror. kind "snapshot": everything; "delta": the
    listed tiles (layer, tx, ty) and, if `objects`, the objects; "none": no
    feed answers (no simulator running)."""

    kind: Literal["snapshot", "delta", "none"]
    tiles: list[tuple[str, int, int]] = field(default_factory=list)
    objects: bool = False
    detail: str = ""


class MapFeed:
    def __init__(
        self,
        session: Any,
        on_update: Callable[[MapUpdate], None],
        *,
        timeout: float = 5.0,
        retry: float = RETRY_S,
    ) -> None:
        self.session = session
        self.on_update = on_update
        self.timeout = timeout
        self.retry = retry
        self._retry_handle: asyncio.TimerHandle | None = None
        self.mirror = MapMirror()
        self.state = WAITING
        self.bytes_received = 0  # payload bytes of deltas and snapshots
        self.resyncs = 0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._sub: Any = None
        self._task: asyncio.Task[None] | None = None
        self._syncing = False
        self._pending: list[MapDelta] = []
        self._closed = False

    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._sub = subscribe(self.session, KEY_MAP_DELTA, self._on_delta)
        await self.resync()

    def close(self) -> None:
        self._closed = True
        if self._retry_handle is not None:
            self._retry_handle.cancel()
        if self._task is not None:
            self._task.cancel()
        sub, self._sub = self._sub, None
        if sub is not None:
            try:
                sub.undeclare()
            except Exception:  # the session may be closed already
                pass

    # -- snapshot ------------------------------------------------------------------
    async def resync(self) -> None:
        """Query the snapshot and apply it with the deltas that came meanwhile."""
        self._syncing = True
        try:
            try:
                raw = await query(self.session, KEY_MAP_SNAPSHOT, b"", self.timeout)
            except (NoResponder, QueryTimeout, QueryFailed) as e:
                if self.state != NONE:
                    self._emit(MapUpdate("none", detail=str(e) or type(e).__name__))
                self.state = NONE
                self._pending.clear()
                if not self._closed and self._loop is not None:
                    self._retry_handle = self._loop.call_later(self.retry, self._retry)
                return
            self.bytes_received += len(raw)
            try:
                snap = MapSnapshot.model_validate_json(raw)
                self.mirror.apply_snapshot(snap)
            except (ValidationError, ValueError) as e:
                log.warning("ignoring a malformed map snapshot: %s", e)
                self.state = NONE
                self._emit(MapUpdate("none", detail="malformed map snapshot"))
                return
            self.resyncs += 1
            pending, self._pending = sorted(self._pending, key=lambda d: d.seq), []
            for d in pending:
                if not self.mirror.apply_delta(d):
                    break  # still a gap: the next delta schedules another resync
            self.state = LIVE
            self._emit(MapUpdate("snapshot", objects=True))
        finally:
            self._syncing = False

    def _retry(self) -> None:
        if self.state == NONE:  # a delta may have brought the feed meanwhile
            self._schedule_resync()

    def _schedule_resync(self) -> None:
        if self._closed or self._syncing or (self._task is not None and not self._task.done()):
            return
        self._task = asyncio.ensure_future(self.resync())

    # -- deltas --------------------------------------------------------------------
    def _on_delta(self, msg: Any) -> None:  # a Zenoh thread
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        try:
            delta = MapDelta.model_validate_json(msg.payload)
        except ValidationError:
            log.warning("ignoring a malformed map delta on %s", msg.key)
            return
        try:
            loop.call_soon_threadsafe(self.got_delta, delta, len(msg.payload))
        except RuntimeError:
            pass  # loop closed

    def got_delta(self, delta: MapDelta, size: int = 0) -> None:
        """Take one delta (on the loop)."""
        if self._closed:
            return
        self.bytes_received += size
        if self._syncing:
            self._pending.append(delta)
            return
        if not self.mirror.ready:
            self._pending.append(delta)
            self._schedule_resync()  # a feed appeared after we looked
            return
        if not self.mirror.apply_delta(delta):
            self._pending.append(delta)
            self._schedule_resync()
            return
        tiles: list[tuple[str, int, int]] = [(t.layer, t.tx, t.ty) for t in delta.tiles]
        if tiles or delta.objects is not None:
            self._emit(MapUpdate("delta", tiles=tiles, objects=delta.objects is not None))

    def _emit(self, update: MapUpdate) -> None:
        try:
            self.on_update(update)
        except Exception:  # a listener's bug must not stop the feed
            log.exception("map feed listener failed")
