"""The client library: what consoles, `missionctl ctl` and scripts use to talk to the server.

`from backend.client import MissionClient` is the scripting API; its listeners
get the typed events of `events` (`ClientEvent`); `mapfollow` follows the
simulator's map feed.
"""

from backend.client.client import (
    ClientError,
    LoginFailed,
    MaybeApplied,
    MissionClient,
    OperationRefused,
    OperationTimeout,
    ProtocolMismatch,
    ServerGone,
    ServerUnreachable,
)
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

__all__ = [
    "AlertRaised",
    "BatchApplied",
    "ClientError",
    "ClientEvent",
    "ConnectionState",
    "LoginFailed",
    "Malformed",
    "MaybeApplied",
    "MissionClient",
    "OperationRefused",
    "OperationTimeout",
    "ProtocolMismatch",
    "RobotChanged",
    "ServerGone",
    "ServerUnreachable",
    "StateSynced",
    "TelemetryReceived",
]
