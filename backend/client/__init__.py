"""The client library: what consoles, `missionctl ctl` and scripts use to talk to the server.

`from backend.client import MissionClient` is the scripting API; `mapfollow`
follows the simulator's map feed.
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

__all__ = [
    "ClientError",
    "LoginFailed",
    "MaybeApplied",
    "MissionClient",
    "OperationRefused",
    "OperationTimeout",
    "ProtocolMismatch",
    "ServerGone",
    "ServerUnreachable",
]
