"""What a `MissionClient` tells its listeners: one small frozen event per kind.

A listener is called on the event loop with one of the `ClientEvent` types
and dispatches on the type (`match event: case BatchApplied(batch=b): ...`).
Each event also has `kind` (the name of its kind: "state", "events",
"fleet", "telemetry", "alert", "connection", "malformed") and `payload`
(what it carries), for renderers keyed by kind such as `missionctl ctl watch`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar, Literal

from backend.core.events import EventBatch
from backend.protocol.keys import PROTOCOL_VERSION
from backend.protocol.messages import Alert, RobotInfo, StateSnapshot, Telemetry


@dataclass(frozen=True, slots=True)
class StateSynced:
    """The mirror was (re)loaded from the server's snapshot: at connect,
    after a gap in the events, after a server restart."""

    kind: ClassVar[str] = "state"
    snapshot: StateSnapshot

    @property
    def payload(self) -> StateSnapshot:
        return self.snapshot


@dataclass(frozen=True, slots=True)
class BatchApplied:
    """An operation's event batch, applied to the mirror."""

    kind: ClassVar[str] = "events"
    batch: EventBatch

    @property
    def payload(self) -> EventBatch:
        return self.batch


@dataclass(frozen=True, slots=True)
class RobotChanged:
    """A robot's presence or manifest changed."""

    kind: ClassVar[str] = "fleet"
    robot: RobotInfo

    @property
    def payload(self) -> RobotInfo:
        return self.robot


@dataclass(frozen=True, slots=True)
class TelemetryReceived:
    """A robot's telemetry sample."""

    kind: ClassVar[str] = "telemetry"
    telemetry: Telemetry

    @property
    def payload(self) -> Telemetry:
        return self.telemetry


@dataclass(frozen=True, slots=True)
class AlertRaised:
    """An alert the server raised."""

    kind: ClassVar[str] = "alert"
    alert: Alert

    @property
    def payload(self) -> Alert:
        return self.alert


@dataclass(frozen=True, slots=True)
class ConnectionState:
    """The link to the server: connected (after each resync) or reconnecting."""

    kind: ClassVar[str] = "connection"
    state: Literal["connected", "reconnecting"]

    @property
    def payload(self) -> str:
        return self.state


@dataclass(frozen=True, slots=True)
class Malformed:
    """A message this client could not read and ignored (the first from its key)."""

    kind: ClassVar[str] = "malformed"
    what: str  # "events", "fleet", "telemetry", "alert"
    key: str
    error: str  # the first validation error: "field.path: message"

    @property
    def payload(self) -> Malformed:
        return self

    def sentence(self) -> str:
        return (
            f"{self.what} on {self.key} could not be read and is ignored: {self.error} "
            f"(does its sender speak missionctl protocol {PROTOCOL_VERSION}? "
            "see docs/protocol.md)"
        )


ClientEvent = (
    StateSynced
    | BatchApplied
    | RobotChanged
    | TelemetryReceived
    | AlertRaised
    | ConnectionState
    | Malformed
)
Listener = Callable[[ClientEvent], None]
