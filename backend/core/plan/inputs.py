"""What predictions and plan checks take besides the mission and the library.

All times are wall-clock seconds since the epoch (floats); durations from
the library are robot seconds, turned into wall seconds by `speed` (a
simulation may run faster than real time). Every input may be missing: a
robot without telemetry is assumed at full battery at an unknown place; no
site map means no coverage or terrain checks; no link model means no delay.
"""

from __future__ import annotations

import bisect
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

from backend.core.plan.geometry import Point


class SiteMap(Protocol):
    """What the plan asks of a site map. Implemented outside the core (the
    map feed's mirror is numpy: backend/client/planning.py). None: the map
    does not know (e.g. outside it)."""

    @property
    def version(self) -> int:
        """Changes whenever an answer may have changed (caches key on it)."""
        ...

    def covered(self, x: float, y: float) -> bool | None:
        """The operator's link reaches this place."""
        ...

    def passable(self, x: float, y: float) -> bool | None:
        """A rover can be here (not rocks)."""
        ...

    def explored(self, x: float, y: float) -> bool | None:
        """Some robot has mapped this place."""
        ...

    def route_length(self, a: Point, b: Point) -> float:
        """Metres a rover drives from a to b (math.inf: no route)."""
        ...

    def home(self) -> Point | None:
        """Where robots recharge (the lander), if the map knows."""
        ...


@dataclass(frozen=True, slots=True)
class RobotNow:
    """A robot's last telemetry sample, as predictions use it."""

    at: float  # when it was taken
    x: float | None = None
    y: float | None = None
    battery: float | None = None  # 0..1
    skill: str | None = None  # the skill it is executing
    progress: float | None = None  # of that skill, 0..1
    eta_s: float | None = None  # robot seconds left of that skill
    mode: str = ""  # "halted": it waits for a run command

    @property
    def position(self) -> Point | None:
        return None if self.x is None or self.y is None else (self.x, self.y)


@dataclass(frozen=True, slots=True)
class LinkModel:
    """The operator's link to a robot: one-way delay and, for distant
    operations, the contact windows (none: always in contact)."""

    one_way_s: float = 0.0
    windows: tuple[tuple[float, float], ...] = ()  # (start, end), sorted, not overlapping

    def reaches(self, t: float) -> float:
        """When a command sent at `t` (or at the next contact) reaches the robot."""
        return self.next_contact(t) + self.one_way_s

    def next_contact(self, t: float) -> float:
        if not self.windows:
            return t
        i = bisect.bisect_right([w[1] for w in self.windows], t)
        if i == len(self.windows):
            return t  # after the last known window: assume contact
        start, _ = self.windows[i]
        return max(t, start)


@dataclass(frozen=True)
class PlanInputs:
    now: float
    robots: Mapping[str, RobotNow] = field(default_factory=dict)
    site: SiteMap | None = None
    link: LinkModel = LinkModel()
    links: Mapping[str, LinkModel] = field(default_factory=dict)  # per robot, over `link`
    speed: float = 1.0  # robot seconds per wall second
    home: Point | None = None  # where robots recharge, when the site map does not say

    def link_of(self, robot: str) -> LinkModel:
        return self.links.get(robot, self.link)

    def home_point(self) -> Point | None:
        found = self.site.home() if self.site is not None else None
        return found if found is not None else self.home

    def site_version(self) -> int:
        return self.site.version if self.site is not None else -1
