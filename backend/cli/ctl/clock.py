"""ctl's mission clock: the times and durations ctl's text shows, in mission time.

Mission time is the simulator's clock while a sim runs (its `sim_time`, at its
`speed`: sim seconds per wall second), wall time otherwise (BRIEF "One mission
clock"; the console's is console/state/clock.py). What ctl reads is stamped
with the wall clock (a command's `created`, when a robot was heard, its
delay): `CtlClock` turns a stamp into `sim h:mm:ss` and a wall duration into
sim seconds. ctl asks the sim's status once per invocation (`ask`); without a
sim the clock is `WALL` and every text is the wall's, as before.
--json output stays in wall stamps and wall seconds.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from backend.core.contact import sim_time_text


def wall_time(t: datetime | None) -> str:
    """A wall stamp as local `HH:MM:SS` ('' for none)."""
    if t is None:
        return ""
    try:
        return t.astimezone().strftime("%H:%M:%S")
    except (ValueError, OSError):
        return t.strftime("%H:%M:%S")


def age_text(seconds: float | None) -> str:
    """12 s, 4 min, 2 h 5 min."""
    if seconds is None:
        return "?"
    s = max(0, round(seconds))
    if s < 120:
        return f"{s} s"
    if s < 7200:
        return f"{s // 60} min"
    return f"{s // 3600} h {s % 3600 // 60} min"


@dataclass(frozen=True)
class CtlClock:
    """The sim said it was `sim_time` when the wall read `wall` (None: no sim)."""

    speed: float = 1.0
    sim_time: float | None = None
    wall: datetime | None = None

    @classmethod
    def of_status(cls, status: Any, wall: datetime | None = None) -> CtlClock:
        """From a `SimStatus` (None, or a stopped sim: the wall's clock)."""
        if status is None or status.speed <= 0:
            return WALL
        return cls(status.speed, status.sim_time, wall or datetime.now(UTC))

    @property
    def simulated(self) -> bool:
        return self.sim_time is not None

    def span(self, wall_seconds: float | None) -> float | None:
        """A wall duration in mission seconds."""
        return None if wall_seconds is None else wall_seconds * self.speed

    def duration(self, wall_seconds: float | None) -> str:
        """A wall duration in mission time: `12 s`, `10 min`."""
        return age_text(self.span(wall_seconds))

    def age(self, t: datetime | None, now: datetime) -> str:
        """How long before `now` wall stamp `t` was, in mission time."""
        return self.duration(None if t is None else (now - t).total_seconds())

    def fine(self, wall_seconds: float) -> str:
        """A short duration (a link delay, a command's answer): to the tenth on
        the wall's clock (`2.0 s`, as ever), in mission time on the sim's (`10 min`)."""
        return self.duration(wall_seconds) if self.simulated else f"{wall_seconds:.1f} s"

    def sim_stamp(self, t: datetime) -> str | None:
        """`sim 0:20:00`; None without a sim, or for a stamp from before this sim run."""
        if self.sim_time is None or self.wall is None:
            return None
        sim = self.sim_time + (t - self.wall).total_seconds() * self.speed
        return f"sim {sim_time_text(sim)}" if sim >= 0 else None

    def stamp(self, t: datetime | None) -> str:
        """`sim 0:20:00`, else the wall's `HH:MM:SS` ('' for none)."""
        return (self.sim_stamp(t) if t is not None else None) or wall_time(t)

    def at(self, t: float) -> str:
        """A wall instant in seconds since the epoch (a forecast's), as `stamp`."""
        return self.stamp(datetime.fromtimestamp(t, UTC))


WALL = CtlClock()


async def ask(client: Any, timeout: float) -> CtlClock:
    """The mission clock now: one query of the sim's status (none answers at
    once when no sim runs: `NoResponder`), else the wall's."""
    from backend.client.planning import fetch_status

    return CtlClock.of_status(await fetch_status(client.session, timeout))
