"""One mission clock: "now", and every time a person reads, in mission time (no Textual here).

Mission time is the simulator's clock while a sim runs (sim seconds since it
started, at its speed: sim seconds per wall second), wall time otherwise. The
sim says its time in its map feed and its status; between those the clock
moves on at the known speed, so it ticks while nothing is reported.

What the console holds is stamped with the wall clock (a command's `created`
and `sent`, when a robot was heard, a log entry, the forecast's times): the
clock turns a stamp into mission time (`of`), a wall duration into a mission
duration (`span`), and writes them with their unit (`time_text`, `age_text`,
`duration_text`). Calling the clock gives the wall time now: that is what the
console stamps things with (and what tests pin: `MissionClock(lambda: T0)`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime

from backend.core.contact import sim_time_text
from console.state.text import fmt_clock, fmt_duration

# a sim report up to this many wall seconds behind the clock's interpolation does
# not set it back (the sim lags under load); more is a new sim run: the clock follows
BACKWARDS_OK_S = 2.0


def wall_now() -> datetime:
    return datetime.now(UTC)


@dataclass(frozen=True, slots=True)
class SimAnchor:
    """The sim said it was `sim_time` when the wall clock read `wall`."""

    sim_time: float
    wall: datetime
    speed: float


def sim_clock_text(seconds: float) -> str:
    """Sim time as h:mm:ss, hours always shown as in the server's and ctl's
    sentences (`sim 0:20:00` is never read as 20 o'clock, and an alert's
    stamp reads like the top bar's): 0:26:48, 1:02:05, -0:00:05 before the start."""
    sign = "-" if seconds <= -1 else ""
    return sign + sim_time_text(abs(seconds))


class MissionClock:
    """Mission time for every view. `clock()` is the wall time now."""

    def __init__(self, wall: Callable[[], datetime] = wall_now) -> None:
        self.wall = wall
        self.anchor: SimAnchor | None = None  # None: no sim heard, mission time is wall time
        self._latest = float("-inf")  # the latest sim time `now` gave (it never goes back)

    def __call__(self) -> datetime:
        return self.wall()

    # -- what the sim says ------------------------------------------------------------------
    def heard(self, sim_time: float, speed: float) -> None:
        """The sim's time is `sim_time` now (its map feed or status said so).
        Safe from another thread: the anchor is replaced in one assignment."""
        if speed <= 0:
            return
        self.anchor = SimAnchor(sim_time, self.wall(), speed)

    @property
    def simulated(self) -> bool:
        return self.anchor is not None

    @property
    def speed(self) -> float:
        """Mission seconds per wall second."""
        return self.anchor.speed if self.anchor is not None else 1.0

    # -- mission time -----------------------------------------------------------------------
    def of(self, t: datetime) -> float:
        """The mission time of a wall stamp (sim seconds; else its POSIX time)."""
        return self.of_ts(t.timestamp())

    def of_ts(self, ts: float) -> float:
        """The mission time of a POSIX time stamp (the forecast's times)."""
        a = self.anchor
        if a is None:
            return ts
        return a.sim_time + (ts - a.wall.timestamp()) * a.speed

    def to_ts(self, m: float) -> float:
        """The POSIX time stamp of mission time `m` (the inverse of `of_ts`)."""
        a = self.anchor
        if a is None:
            return m
        return a.wall.timestamp() + (m - a.sim_time) / a.speed

    def now(self) -> float:
        """Mission time now; a sim's clock never goes back by a lag."""
        m = self.of(self.wall())
        if self.anchor is None:
            return m
        if self._latest - BACKWARDS_OK_S * self.anchor.speed < m < self._latest:
            return self._latest
        self._latest = m
        return m

    def span(self, wall_seconds: float) -> float:
        """A wall duration in mission seconds."""
        return wall_seconds * self.speed

    def since(self, t: datetime) -> float:
        """Mission seconds from wall stamp `t` to now (0 if in the future)."""
        return max(0.0, self.span((self.wall() - t).total_seconds()))

    # -- in words ---------------------------------------------------------------------------
    def time_text(self, m: float, *, seconds: bool = True) -> str:
        """A mission time: '0:26:48' (sim), '15:42:10' (wall, local; '15:42' without seconds)."""
        if self.anchor is not None:
            return sim_clock_text(m)
        text = fmt_clock(datetime.fromtimestamp(m, UTC))
        return text if seconds else text[:5]

    def stamp_text(self, t: datetime | None) -> str:
        """When a wall stamp was, in mission time: 'sim 0:26:48' or '15:42:10'."""
        if t is None:
            return "--:--:--"
        return self.ts_text(t.timestamp())

    def ts_text(self, ts: float) -> str:
        """`stamp_text` of a POSIX time stamp (the forecast's times)."""
        return f"{self.unit_prefix}{self.time_text(self.of_ts(ts))}"

    @property
    def unit_prefix(self) -> str:
        """What says a time is the sim's ('sim '), before it; '' for wall time."""
        return "sim " if self.anchor is not None else ""

    def now_text(self) -> str:
        """'sim 0:26:48' (the top bar)."""
        return f"{self.unit_prefix}{self.time_text(self.now())}"

    def duration_text(self, wall_seconds: float | None) -> str:
        """A wall duration in mission time: '36s', '3m46s'."""
        return fmt_duration(None if wall_seconds is None else self.span(wall_seconds))

    def age_text(self, t: datetime) -> str:
        """How long ago wall stamp `t` was, in mission time: '36s'."""
        return fmt_duration(self.since(t))
