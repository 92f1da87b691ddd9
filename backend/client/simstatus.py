"""Following the simulator's live status from a client session (consoles, scripts).

    feed = SimStatusFeed(session)
    await feed.start()          # subscribes, then queries the status
    feed.status                 # the latest SimStatus, or None (no simulator)
    feed.close()

The late-join rule of the map feed (backend/client/mapfollow.py): subscribe
first, then query the status, then apply the publications that follow it
(`backend.protocol.mapfeed.StatusMirror`: full statuses and merge patches).
A gap or a restarted simulator queries again; nobody answering is normal (no
simulator): the next full publication brings the status.

Zenoh callbacks only hand the payload to the asyncio loop (subscribe_on_loop).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any

from pydantic import ValidationError

from backend.protocol.mapfeed import KEY_STATUS, KEY_STATUS_LIVE, SimStatus, StatusMirror
from backend.transport import QueryFailed, query, subscribe_on_loop, undeclare

log = logging.getLogger(__name__)


class SimStatusFeed:
    def __init__(
        self,
        session: Any,
        on_update: Callable[[SimStatus], object] | None = None,
        *,
        timeout: float = 5.0,
    ) -> None:
        self.session = session
        self.on_update = on_update
        self.timeout = timeout
        self.mirror = StatusMirror()
        self.queries = 0  # status queries made (first one and after gaps)
        self._sub: Any = None
        self._task: asyncio.Task[None] | None = None
        self._early: list[bytes] = []  # publications that came while querying
        self._querying = False
        self._closed = False
        self._said_malformed = False

    @property
    def status(self) -> SimStatus | None:
        return self.mirror.status

    async def start(self) -> None:
        self._sub = subscribe_on_loop(self.session, KEY_STATUS_LIVE, self._got)
        await self.resync()

    def close(self) -> None:
        self._closed = True
        if self._task is not None:
            self._task.cancel()
        sub, self._sub = self._sub, None
        undeclare(sub)

    async def resync(self) -> None:
        """Query the status and apply it with the publications that came meanwhile."""
        self._querying = True
        self.queries += 1
        try:
            raw = await query(self.session, KEY_STATUS, b"", self.timeout)
            self.mirror.apply_full(SimStatus.model_validate_json(raw))
        except (QueryFailed, ValidationError, ValueError) as e:
            log.debug("no simulator status: %s", e)  # none runs: its next full one will do
        finally:
            self._querying = False
        early, self._early = self._early, []
        for payload in early:
            self._apply(payload)
        self._emit()

    def _got(self, payload: bytes) -> None:
        if self._closed:
            return
        if self._querying:
            self._early.append(payload)
            return
        if self._apply(payload):
            self._emit()

    def _apply(self, payload: bytes) -> bool:
        try:
            ok = self.mirror.apply(payload)
        except (ValidationError, ValueError) as e:
            if not self._said_malformed:
                self._said_malformed = True
                log.warning("ignoring a malformed simulator status: %s", e)
            return False
        if not ok:
            self._schedule_resync()
        return ok

    def _schedule_resync(self) -> None:
        if self._closed or self._querying or (self._task is not None and not self._task.done()):
            return
        self._task = asyncio.ensure_future(self.resync())

    def _emit(self) -> None:
        status = self.mirror.status
        if status is not None and self.on_update is not None:
            self.on_update(status)
