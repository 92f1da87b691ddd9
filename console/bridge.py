"""The live connection: `backend.client.client.MissionClient` -> console messages.

The client calls its listeners on the asyncio loop (the app's loop) with a
typed event (`backend.client.events`); each becomes one posted console
message, so nothing here ever blocks the UI. Operations go through
`submit`, awaited in workers by the app.
"""

from __future__ import annotations

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
from backend.protocol.keys import Keys
from backend.protocol.mapfeed import KEY_STATUS_LIVE, SimStatus
from backend.protocol.messages import OpReply
from backend.transport import subscribe
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
        self.sim_status: SimStatus | None = None  # the simulator's speed and link delay (plans)
        self._status_sub: Any = None

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
        feed = MapFeed(self.client.session, self._on_map)
        self.map_feed = feed
        self._status_sub = subscribe(self.client.session, KEY_STATUS_LIVE, self._on_status)
        await feed.start()

    def _on_status(self, msg: Any) -> None:  # a Zenoh thread: keep the latest, nothing else
        try:
            status = SimStatus.model_validate_json(msg.payload)
        except ValueError:
            return  # not a status of ours: the plan goes on without the sim's speed
        self.sim_status = status
        self.app.model.clock.heard(status.sim_time, status.speed)  # thread-safe (clock.py)

    def _on_map(self, update: MapUpdate) -> None:
        feed = self.map_feed
        if feed is not None:
            self.app.post_message(MapChanged(feed.mirror, update))

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
