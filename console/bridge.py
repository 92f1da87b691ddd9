"""The live connection: `backend.client.client.MissionClient` -> console messages.

The client calls its listeners on the asyncio loop (the app's loop) with a
typed event (`backend.client.events`); each becomes one posted console
message, so nothing here ever blocks the UI. Operations go through
`submit`, awaited in workers by the app.
"""

from __future__ import annotations

import asyncio
from typing import Any, Protocol

from backend.client.client import MissionClient
from backend.client.events import (
    AlertRaised,
    BatchApplied,
    ClientEvent,
    ConnectionState,
    Malformed,
    RobotChanged,
    StateSynced,
    TelemetryReceived,
)
from backend.client.mapfollow import MapFeed, MapUpdate
from backend.client.simstatus import SimStatusFeed
from backend.protocol.keys import Keys
from backend.protocol.mapfeed import SimStatus
from backend.protocol.messages import OpReply
from backend.transport.login import Login
from console.messages import (
    AccountKnown,
    AlertReceived,
    ConnectionChanged,
    EventsApplied,
    FleetChanged,
    MapChanged,
    MessageUnreadable,
    StateLoaded,
    TelemetryChanged,
)


class Backend(Protocol):
    """What the console needs to change the mission (the client, or a test double)."""

    async def submit(self, op: Any, *, expected_revision: int | None = None) -> OpReply: ...


class ClientBridge:
    def __init__(
        self,
        app: Any,
        endpoint: str,
        *,
        user: str = "",
        client_id: str | None = None,
        login: Login | None = None,
    ) -> None:
        self.app = app
        self.endpoint = endpoint
        self.user = user
        self.client_id = client_id
        self.login = login
        self.client: MissionClient | None = None
        self.map_feed: MapFeed | None = None
        self._status_feed: SimStatusFeed | None = None
        self._speed: float | None = None  # the sim's, as last told to the app

    async def connect(self) -> None:
        """Connect (raises backend.client.client.ClientError with a sentence)."""
        await self.close()
        client = MissionClient(
            self.endpoint, user=self.user, client_id=self.client_id, login=self.login
        )
        client.add_listener(self._on_client)
        self.client = client
        try:
            await client.connect()
        except BaseException:
            self.client = None
            raise
        self.app.post_message(AccountKnown(client.read_only or ""))
        await self.follow_map()

    async def follow_map(self) -> None:
        """Follow the simulator's map feed on the client's session (nobody
        answering is fine: the map screen then says there is no feed)."""
        if self.client is None or self.client.session is None:
            return
        feed = MapFeed(self.client.session, self._on_map, timeout=self.client.timeout)
        self.map_feed = feed
        self._status_feed = SimStatusFeed(
            self.client.session, self._on_status, timeout=self.client.timeout
        )
        await asyncio.gather(self._status_feed.start(), feed.start())

    @property
    def sim_status(self) -> SimStatus | None:
        """The simulator's speed and link delay (plans); None without a simulator."""
        return self._status_feed.status if self._status_feed is not None else None

    def _on_status(self, status: SimStatus) -> None:
        """The top bar's sim clock runs at the sim's speed: once it is known (the
        status may come after the map), the clock is set again from the map."""
        if status.speed == self._speed:
            return
        self._speed = status.speed
        feed = self.map_feed
        if feed is not None and feed.mirror.ready:
            self.app.post_message(MapChanged(feed.mirror, MapUpdate("delta")))

    def _on_map(self, update: MapUpdate) -> None:
        feed = self.map_feed
        if feed is not None:
            self.app.post_message(MapChanged(feed.mirror, update))

    async def close(self) -> None:
        status_feed, self._status_feed = self._status_feed, None
        if status_feed is not None:
            status_feed.close()
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
            from backend.client.client import ClientError

            raise ClientError("not connected to the mission server")
        return await self.client.submit(op, expected_revision=expected_revision)

    # -- client events (on the loop) -> messages ----------------------------------------
    def _on_client(self, event: ClientEvent) -> None:
        c = self.client
        post = self.app.post_message
        match event:
            case StateSynced(snapshot=snap):
                if c is not None and c.mission is not None and c.library is not None:
                    post(StateLoaded(c.mission, c.library, dict(c.robots), snap.server_id))
            case BatchApplied(batch=batch):
                if c is not None:
                    post(EventsApplied(batch, c.mission))
            case RobotChanged(robot=info):
                post(FleetChanged(info))
            case TelemetryReceived(telemetry=t):
                post(TelemetryChanged(t))
            case AlertRaised(alert=a):
                post(AlertReceived(a))
            case Malformed():
                robot = Keys.robot_of(event.key) if "/robot/" in event.key else None
                post(MessageUnreadable(event.what, event.key, event.sentence(), robot))
            case ConnectionState(state=state):
                post(ConnectionChanged(state, endpoint=self.endpoint))
