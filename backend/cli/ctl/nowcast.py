"""`ctl state --nowcast`: each robot's probable present beside its last report.

What a console draws with ≈: from each robot's last telemetry, its course and
the mission time elapsed since (backend/core/plan/nowcast.py), the skill it
probably executes and how far, where it probably is, its battery, and how
old the report it starts from is.
"""

from __future__ import annotations

import time
from typing import Any

from backend.cli.ctl.clock import WALL, CtlClock
from backend.cli.ctl.plan import gather_clocked
from backend.core.plan.forecast import Forecaster
from backend.core.plan.nowcast import nowcasts


async def nowcasts_json(
    client: Any, args: Any, only: list[str]
) -> tuple[dict[str, Any], CtlClock | None]:
    """--nowcast: {"nowcast": {robot: its probable present, or None}} ({} without it),
    and the mission clock of the sim status it asked (None: it asked none)."""
    if not getattr(args, "nowcast", False):
        return {}, None
    inputs, clock = await gather_clocked(client, args.timeout)
    every = _every_nowcast(client, inputs)
    found = {r: every.get(r) for r in only or list(client.mission.robots)}
    return {"nowcast": {r: nc.as_json() if nc else None for r, nc in found.items()}}, clock


def _every_nowcast(client: Any, inputs: Any) -> dict[str, Any]:
    """Each robot's probable present, from its course and its link."""
    m = client.mission
    forecaster = Forecaster(client.library)
    courses = {r: forecaster.course(m, r, inputs) for r in m.robots}
    links = {r: inputs.link_of(r) for r in courses}
    return nowcasts(courses, m, time.time(), inputs.speed, links)


def nowcasts_text(predicted: dict[str, Any], clock: CtlClock = WALL) -> str:
    """One line per robot, after the state ('' without --nowcast)."""
    lines = [nowcast_line(r, nc, clock) for r, nc in predicted.get("nowcast", {}).items()]
    return "".join(f"\n{line}" for line in lines)


def nowcast_line(robot: str, nc: dict[str, Any] | None, clock: CtlClock = WALL) -> str:
    """'≈ lru1 now: lru1-5 62% at (12.0, -3.5), battery 41% (from a report 10 min old)'."""
    if nc is None:
        return f"≈ {robot}: no telemetry to predict from"
    old = _age(nc["age_s"], clock)
    return f"≈ {robot} now: {_doing(nc)}{_where(nc)} (from a report {old} old)"


def _age(age_s: float, clock: CtlClock) -> str:
    """The report's age: wall seconds as ever (`600 s`), in mission time with a sim."""
    return clock.duration(age_s) if clock.simulated else f"{age_s:.0f} s"


def _doing(nc: dict[str, Any]) -> str:
    if nc["skill"] is None:
        return f"no skill, waiting ({nc['held']})" if nc["held"] else "no skill"
    return f"{nc['skill']} {nc['progress'] or 0:.0%}"


def _where(nc: dict[str, Any]) -> str:
    at = "" if nc["x"] is None else f" at ({nc['x']:.1f}, {nc['y']:.1f})"
    return at + ("" if nc["battery"] is None else f", battery {nc['battery']:.0%}")
