"""The messages that bring state into the console.

The live connection (`console.bridge`) turns client-library callbacks into
these; tests post them directly, which is what makes snapshots deterministic
and lets every screen be tested without a network.
"""

from __future__ import annotations

from typing import Any

from textual.message import Message

from backend.core.events import EventBatch
from backend.core.library import Library
from backend.core.model import Mission
from backend.protocol.messages import Alert, RobotInfo, Telemetry


class StateLoaded(Message):
    """A full state: first connection, a resync after a gap or a server restart."""

    def __init__(
        self,
        mission: Mission,
        library: Library,
        robots: dict[str, RobotInfo] | None = None,
        server_id: str = "",
    ) -> None:
        super().__init__()
        self.mission = mission
        self.library = library
        self.robots = robots
        self.server_id = server_id


class EventsApplied(Message):
    """One applied operation. `mission` is the client's mirror with the batch
    already applied; None means: apply `batch` to the console's own copy."""

    def __init__(self, batch: EventBatch, mission: Mission | None = None) -> None:
        super().__init__()
        self.batch = batch
        self.mission = mission


class FleetChanged(Message):
    def __init__(self, info: RobotInfo) -> None:
        super().__init__()
        self.info = info


class TelemetryChanged(Message):
    def __init__(self, telemetry: Telemetry) -> None:
        super().__init__()
        self.telemetry = telemetry


class ConnectionChanged(Message):
    """status: connecting | connected | reconnecting | unreachable | offline."""

    def __init__(self, status: str, detail: str = "", endpoint: str | None = None) -> None:
        super().__init__()
        self.status = status
        self.detail = detail
        self.endpoint = endpoint


class AccountKnown(Message):
    """The logged-in account's role is known; `read_only` says why this console
    cannot change the mission ("" when it can)."""

    def __init__(self, read_only: str = "") -> None:
        super().__init__()
        self.read_only = read_only


class AlertReceived(Message):
    def __init__(self, alert: Alert) -> None:
        super().__init__()
        self.alert = alert


class MessageUnreadable(Message):
    """A message from the network the client library could not read (first
    from its key): a robot or tool speaking another protocol, most likely."""

    def __init__(self, what: str, key: str, text: str, robot: str | None) -> None:
        super().__init__()
        self.what = what
        self.key = key
        self.text = text
        self.robot = robot


class MapChanged(Message):
    """The map feed changed: `mirror` is the follower's mirror (read it, never
    change it), `update` says what changed (backend.client.mapfollow.MapUpdate)."""

    def __init__(self, mirror: Any, update: Any) -> None:
        super().__init__()
        self.mirror = mirror
        self.update = update
