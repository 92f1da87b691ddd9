"""The downlink (robot -> ground) of every simulated robot: what a robot has to
tell waits aboard until it is in coverage and the ground is in contact (a
comms window), then travels one link delay to the ground view.

With its news a robot sends the cells it explored since it last could, and
its own state (pose, battery, activity, last result). A robot that crossed
covered ground between two pumps sent from there.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from sim.ground import CellsSeen, GroundView, News, RobotHeard, RobotState
from sim.robot import SimRobot


@dataclass
class Aboard:
    """One robot's side of its downlink."""

    waiting: list[News] = field(default_factory=list)  # until it can send
    in_flight: list[tuple[float, News]] = field(default_factory=list)  # (arrival, news)
    cells: np.ndarray | None = None  # explored, not sent yet
    passed_coverage: bool = False  # moved through coverage since the last pump


class DownlinkPump:
    """Moves news from the robots to the ground view."""

    def __init__(self, ground: GroundView, shape: tuple[int, int]):
        self.ground = ground
        self.shape = shape
        self.aboard: dict[str, Aboard] = {}

    def of(self, robot: SimRobot) -> Aboard:
        found = self.aboard.get(robot.name)
        if found is None:
            found = self.aboard[robot.name] = Aboard(cells=np.zeros(self.shape, dtype=bool))
        return found

    def send(self, robot: SimRobot, news: News) -> None:
        """It reaches the ground once the robot can send (plus the link delay)."""
        self.of(robot).waiting.append(news)

    def explored(self, robot: SimRobot, rows: slice, cols: slice, new: np.ndarray) -> None:
        """Cells the robot mapped that the ground does not know: they go with its news."""
        cells = self.of(robot).cells
        assert cells is not None
        cells[rows, cols] |= new

    def crossed_coverage(self, robot: SimRobot) -> None:
        """The robot was in coverage at some moment since the last pump."""
        self.of(robot).passed_coverage = True

    def pump(
        self,
        robots: Iterable[SimRobot],
        now: float,
        delay: float,
        *,
        ground_open: bool,
        in_range: Callable[[SimRobot], bool],
        state_of: Callable[[SimRobot], RobotState],
    ) -> bool:
        """Put what robots that can send have aboard on the link (and their
        state); deliver what has arrived. `now` and `delay` in wall seconds;
        out of a comms window (`ground_open` False) nothing leaves, what is on
        its way arrives. True if anything arrived."""
        arrived = False
        for robot in robots:
            a = self.of(robot)
            passed, a.passed_coverage = a.passed_coverage, False
            if ground_open and (in_range(robot) or passed):
                self._leave(robot, a, now + delay, state_of)
            if a.in_flight and self._arrive(a, now):
                arrived = True
        return arrived

    def _leave(
        self, robot: SimRobot, a: Aboard, at: float, state_of: Callable[[SimRobot], RobotState]
    ) -> None:
        assert a.cells is not None
        if a.cells.any():
            cells = np.flatnonzero(a.cells)
            a.cells[:] = False
            a.waiting.append(CellsSeen(cells))
        a.waiting.append(RobotHeard(robot.name, state_of(robot)))
        a.in_flight += [(at, news) for news in a.waiting]
        a.waiting = []

    def _arrive(self, a: Aboard, now: float) -> bool:
        due = [news for t, news in a.in_flight if t <= now]
        if not due:
            return False
        a.in_flight = [(t, news) for t, news in a.in_flight if t > now]
        for news in due:
            news.reach(self.ground)
        return True
