"""The simulator's score and clock as the ground knows them (no Textual here).

The map feed carries the score the robots reported (`objects.score`) and the
sim time of each message; the simulator's status carries its speed (sim
seconds per wall second). Between messages the clock moves on at that speed,
so the line keeps counting while nothing is reported. Without a simulator
(a real fleet) there is no site line at all.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime


@dataclass(frozen=True)
class SiteClock:
    """The latest score and sim time heard, `at` the console's clock then."""

    score: float
    sim_time: float
    at: datetime
    speed: float | None = None  # unknown until the simulator's status arrives

    def sim_now(self, now: datetime) -> float:
        if not self.speed:
            return self.sim_time
        return self.sim_time + max(0.0, (now - self.at).total_seconds()) * self.speed


def sim_clock_text(seconds: float) -> str:
    """Mission time as a clock: 26:48, 1:02:05 past an hour."""
    s = max(0, int(seconds))
    h, rest = divmod(s, 3600)
    m, sec = divmod(rest, 60)
    return f"{h}:{m:02d}:{sec:02d}" if h else f"{m}:{sec:02d}"


def site_text(site: SiteClock, now: datetime) -> str:
    """'score 1.9 · sim 26:48': the score as reported and the sim clock."""
    return f"score {site.score:g} · sim {sim_clock_text(site.sim_now(now))}"
