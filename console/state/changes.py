"""What the console's model takes in, and the one notice it gives out — no Textual here.

In: the client library's typed events (`backend.client.events.ClientEvent`)
as they are, and the few the console says about itself (`ConsoleEvent`: it
is connecting, the server is unreachable, the account is read-only, the map
feed moved, a mission file's plan is previewed). `ConsoleModel.take` applies
one and answers a `StateChange`.

Out: a `StateChange` says which topics changed and, where it matters, for which
robots. The app publishes it on one signal; every screen and widget that
shows something subscribes and redraws what it shows of those topics, in its
own callback.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from backend.client.events import ClientEvent
from console.state.eventlog import AlertEntry


class Topic(StrEnum):
    MISSION = "mission"  # the plan or its execution: skills, barriers, markers, commands
    FLEET = "fleet"  # a robot's presence, manifest or link
    TELEMETRY = "telemetry"  # a robot's telemetry sample
    CONNECTION = "connection"  # the link to the server, the account
    LOG = "log"  # new event-log entries
    ALERTS = "alerts"  # alerts raised or acknowledged
    MAP = "map"  # the simulator's map feed (and its score and clock)
    FORECAST = "forecast"  # the plan's forecast (the timeline)
    FINDINGS = "findings"  # the plan checks' findings (glyphs, what sync allows)


@dataclass(frozen=True, slots=True)
class StateChange:
    """What one input changed.

    - `topics`: what changed;
    - `robots`: whose state changed, for MISSION the robots whose columns
      change (empty: none; None: any, e.g. a whole new state);
    - `loaded`: a whole state came (the first, or a resync);
    - `revision` / `moved`: the operation's revision and the skills it
      added or moved (a cursor waiting for an undo follows them);
    - `alerts`: alerts it raised; `notified`: their notification was shown
      already (the console's own refusals);
    - `map_update`: for MAP, what changed in the feed's mirror.
    """

    topics: frozenset[Topic] = frozenset()
    robots: frozenset[str] | None = None
    loaded: bool = False
    revision: int | None = None
    moved: tuple[str, ...] = ()
    alerts: tuple[AlertEntry, ...] = ()
    notified: bool = False
    map_update: Any = None  # backend.client.mapfollow.MapUpdate

    def __bool__(self) -> bool:
        return bool(self.topics)

    def about(self, topic: Topic) -> bool:
        return topic in self.topics


NOTHING = StateChange()


def change(
    *topics: Topic, robots: frozenset[str] | set[str] | None = None, **kw: Any
) -> StateChange:
    return StateChange(frozenset(topics), None if robots is None else frozenset(robots), **kw)


# -- what the console says about itself --------------------------------------------


@dataclass(frozen=True, slots=True)
class Connecting:
    """This console is connecting to `endpoint` (at start, or retrying);
    `detail` says what it waits for ("" : the server's answer)."""

    endpoint: str
    detail: str = ""


@dataclass(frozen=True, slots=True)
class Unreachable:
    """No server could be reached: `detail` says why."""

    detail: str


@dataclass(frozen=True, slots=True)
class AccountKnown:
    """The account's role is known; `read_only` says why this console cannot
    change the mission ("" when it can)."""

    read_only: str = ""


@dataclass(frozen=True, slots=True)
class MapFed:
    """The simulator's map feed moved: `mirror` is the follower's mirror (read
    it, never change it), `update` what changed (mapfollow.MapUpdate), `speed`
    the simulator's (None: not known)."""

    mirror: Any
    update: Any
    speed: float | None = None


@dataclass(frozen=True, slots=True)
class Previewed:
    """The plan from a mission file, shown until the server's state replaces
    it (the demo paints at once while its server starts)."""

    mission: Any  # backend.core.model.Mission
    library: Any  # backend.core.library.Library


ConsoleEvent = Connecting | Unreachable | AccountKnown | MapFed | Previewed
ModelEvent = ClientEvent | ConsoleEvent
