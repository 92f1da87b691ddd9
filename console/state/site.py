"""The simulator's score as the ground knows it (no Textual here).

The map feed carries the score the robots reported (`objects.score`); the top
bar shows it beside the mission clock (console/state/clock.py), which the same
feed sets. Without a simulator (a real fleet) there is no site line at all.
"""

from __future__ import annotations

from dataclasses import dataclass

from console.state.clock import MissionClock


@dataclass(frozen=True)
class Site:
    """The latest score the robots reported."""

    score: float


def site_text(site: Site, clock: MissionClock) -> str:
    """'score 1.9 · sim 26:48': the score as reported and the mission clock."""
    return f"score {site.score:g} · {clock.now_text()}"
