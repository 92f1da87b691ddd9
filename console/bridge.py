"""The live connection: a `MissionClient` without a mirror of its own, and the map feed.

The client calls its listeners on the asyncio loop (the app's loop) with a
typed event (`backend.client.events`); each is handed to `post` as it is
(the app posts it to itself, and its model takes it), so nothing here ever
blocks the UI. The client keeps no copy of the mission (`mirror=False`): the
console's model is the one mirror. Operations go through `submit`, awaited
in workers by the `OperationService`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from backend.client.client import ClientError, MissionClient
from backend.client.mapfollow import MapFeed, MapUpdate
from backend.protocol.mapfeed import KEY_STATUS_LIVE, SimStatus
from backend.protocol.messages import OpReply
from backend.transport import subscribe
from backend.transport.login import Login
from console.state.changes import AccountKnown, MapFed, ModelEvent


class ClientBridge:
    def __init__(
        self,
        post: Callable[[ModelEvent], object],
        endpoint: str,
        *,
        user: str = "",
        client_id: str | None = None,
        login: Login | None = None,
    ) -> None:
        self.post = post
        self.endpoint = endpoint
        self.user = user
        self.client_id = client_id
        self.login = login
        self.client: MissionClient | None = None
        self.map_feed: MapFeed | None = None
        self.sim_status: SimStatus | None = None  # the simulator's speed and link delay (plans)
        self._status_sub: Any = None

    async def connect(self) -> None:
        """Connect (raises backend.client.client.ClientError with a sentence)."""
        await self.close()
        client = MissionClient(
            self.endpoint, user=self.user, client_id=self.client_id, login=self.login, mirror=False
        )
        client.add_listener(self.post)
        self.client = client
        try:
            await client.connect()
        except BaseException:
            self.client = None
            raise
        self.post(AccountKnown(client.read_only or ""))
        await self.follow_map()

    async def follow_map(self) -> None:
        """Follow the simulator's map feed on the client's session (nobody
        answering is fine: the map screen then says there is no feed)."""
        if self.client is None or self.client.session is None:
            return
        feed = MapFeed(self.client.session, self._on_map)
        self.map_feed = feed
        self._status_sub = subscribe(self.client.session, KEY_STATUS_LIVE, self._on_status)
        await feed.start()

    def _on_status(self, msg: Any) -> None:  # a Zenoh thread: keep the latest, nothing else
        try:
            self.sim_status = SimStatus.model_validate_json(msg.payload)
        except ValueError:
            pass  # not a status of ours: the plan goes on without the sim's speed

    def _on_map(self, update: MapUpdate) -> None:
        feed = self.map_feed
        if feed is not None:
            status = self.sim_status
            self.post(MapFed(feed.mirror, update, status.speed if status is not None else None))

    async def close(self) -> None:
        sub, self._status_sub = self._status_sub, None
        if sub is not None:
            try:
                sub.undeclare()
            except Exception:  # the session may be closed already
                pass
        feed, self.map_feed = self.map_feed, None
        if feed is not None:
            feed.close()
        client, self.client = self.client, None
        if client is not None:
            await client.close()

    def close_now(self) -> None:
        """Synchronous close for the last moment (after the app loop ended)."""
        client, self.client = self.client, None
        if client is not None:
            client.close_now()

    async def submit(self, op: Any, *, expected_revision: int | None = None) -> OpReply:
        if self.client is None:
            raise ClientError("not connected to the mission server")
        return await self.client.submit(op, expected_revision=expected_revision)
