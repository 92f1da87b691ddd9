"""The console's messages: state coming in, and what the screens ask of the app.

State in: the live connection (`console.bridge`) turns client-library
callbacks into these; tests post them directly, which is what makes snapshots
deterministic and lets every screen be tested without a network.

Requests up (at the end): a screen never imports the app; it posts one of
these and the app handles it (messages up, state down).
"""

from __future__ import annotations

from collections.abc import Callable
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


# -- requests up: what a screen asks of the app -----------------------------------------


class OperationRequested(Message):
    """Submit `op` (in a worker: the UI never waits on the network). `what`
    names it in the status line and notifications; `robot` and `skill` say
    whom a refusal is about; `on_ok(reply)` / `on_refused(error_reply)` run
    after; `say(text, severity)` is the status line to report on (None: the
    mission screen's)."""

    def __init__(
        self,
        op: Any,
        what: str,
        *,
        robot: str | None = None,
        skill: str | None = None,
        expected_revision: int | None = None,
        on_ok: Callable[[Any], object] | None = None,
        on_refused: Callable[[Any], object] | None = None,
        say: Callable[..., object] | None = None,
    ) -> None:
        super().__init__()
        self.op = op
        self.what = what
        self.robot = robot
        self.skill = skill
        self.expected_revision = expected_revision
        self.on_ok = on_ok
        self.on_refused = on_refused
        self.say = say


class HelpRequested(Message):
    """F1 / ?: show the key map (with the user's remappings)."""


class AlertAcknowledged(Message):
    """The operator acknowledged an alert (`alert_id` None: all of them)."""

    def __init__(self, alert_id: int | None) -> None:
        super().__init__()
        self.alert_id = alert_id
