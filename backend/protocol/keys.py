"""The wire protocol's key space (Zenoh key expressions), versioned by PROTOCOL_VERSION.

Documented for third parties in docs/protocol.md. Bump PROTOCOL_VERSION on any
incompatible change of a key or of a message (backend.protocol.messages).
"""

from __future__ import annotations

PROTOCOL_VERSION = 2
PREFIX = f"mc/v{PROTOCOL_VERSION}"


class Keys:
    """The key space. `{robot}` is a robot name, `{session}` one run of a
    robot agent; `*` matches one chunk."""

    # server side
    SERVER_ALIVE = f"{PREFIX}/server/alive"  # liveliness token of the mission server
    OP = f"{PREFIX}/server/op"  # queryable: Request -> OpReply | ErrorReply
    STATE = f"{PREFIX}/server/state"  # queryable: StateRequest -> StateSnapshot
    EVENTS = f"{PREFIX}/server/events"  # publication: EventBatch, revisions consecutive
    FLEET = f"{PREFIX}/server/fleet"  # publication: FleetEvent
    ALERTS = f"{PREFIX}/server/alerts"  # publication: Alert
    HISTORY = f"{PREFIX}/server/history"  # queryable: HistoryRequest -> HistoryReply
    # queryable: anything -> b"pong" (raw-transport baseline for benchmarks)
    PING = f"{PREFIX}/server/ping"

    @staticmethod
    def op_as(
        user: str,
    ) -> str:  # queryable: Request -> OpReply | ErrorReply, from a logged-in user
        return f"{PREFIX}/server/op/{user}"

    @staticmethod
    def account(user: str) -> str:  # queryable: anything -> AccountInfo
        return f"{PREFIX}/server/account/{user}"

    @staticmethod
    def register(robot: str) -> str:  # queryable: Register -> RegisterReply
        return f"{PREFIX}/server/register/{robot}"

    @staticmethod
    def downlink(robot: str) -> str:  # queryable: Downlink -> DownlinkAck
        return f"{PREFIX}/server/downlink/{robot}"

    # robot side
    @staticmethod
    def alive(robot: str, session: str = "*") -> str:  # liveliness token of a robot agent
        return f"{PREFIX}/robot/{robot}/alive/{session}"

    @staticmethod
    def uplink(robot: str) -> str:  # queryable on the robot: Uplink -> UplinkReceipt
        return f"{PREFIX}/robot/{robot}/uplink"

    @staticmethod
    def telemetry(robot: str) -> str:  # publication: Telemetry
        return f"{PREFIX}/robot/{robot}/telemetry"

    @staticmethod
    def world(robot: str) -> str:  # queryable on the robot: WorldMessage -> WorldReply
        return f"{PREFIX}/robot/{robot}/world"

    @staticmethod
    def barrier_ready(barrier: str, robot: str) -> str:  # liveliness token while waiting
        return f"{PREFIX}/barrier/{barrier}/ready/{robot}"

    ALL_ALIVE = f"{PREFIX}/robot/*/alive/*"
    ALL_TELEMETRY = f"{PREFIX}/robot/*/telemetry"

    @staticmethod
    def robot_of(key: str) -> str:
        """Robot name in a `PREFIX/robot/{robot}/...` key or a server key
        ending in `/{robot}` (any robot name, `robot` too)."""
        parts = key.split("/")
        if len(parts) > 3 and parts[2] == "robot":
            return parts[3]
        return parts[-1]

    @staticmethod
    def session_of(key: str) -> str:
        """The session of a robot's liveliness token key."""
        return key.rsplit("/", 1)[-1]

    @staticmethod
    def legacy(version: int) -> str:
        """The server keys of an older protocol version (the server answers
        there that it speaks another one)."""
        return f"mc/v{version}/server/**"
