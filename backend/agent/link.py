"""The operator link as the robot sees it: a model the integrator (or the
simulator) sets, polled by the agent."""

from __future__ import annotations


class Link:
    """The operator link as the robot sees it. No-op by default (always in range).

    A simulator sets `reachable` (or overrides `in_range`), `delay_s` (one-way
    delay applied before each command is handled, before each report flush
    and to each telemetry message) and `quality` (0..1, shown in telemetry).
    Override `can_reach(robot)` to model robot-to-robot links: an ask/tell to
    a robot it cannot reach is not sent and counts as failed.
    """

    def __init__(self, *, reachable: bool = True, delay_s: float = 0.0, quality: float = 1.0):
        self.reachable = reachable
        self.delay_s = delay_s
        self.quality = quality

    def in_range(self) -> bool:
        return self.reachable

    def can_reach(self, robot: str) -> bool:
        return True
