"""Each robot's probable present, as the console draws it with ≈ (no Textual here).

From the plan's forecast (its courses start from each robot's last telemetry)
the now-cast (backend/core/plan/nowcast.py) walks on to the present: the skill
a robot probably executes and how far, where it probably is, its battery.
It is drawn apart from what the robot reported (≈, hollow on the map), and
only when what the console knows of the robot is its last known state
(`robot_nowcast`: stale, console/state/freshness.py).

When a robot's next report arrives, the prediction the last forecast made for
that report's time is compared with it: the error (position, progress, battery)
is logged and kept per robot (`errors`).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from backend.client.planning import link_of
from backend.core.model import Mission
from backend.core.plan.forecast import Forecast
from backend.core.plan.nowcast import Nowcast, nowcasts
from backend.protocol.mapfeed import SimStatus
from backend.protocol.messages import Telemetry

log = logging.getLogger(__name__)

NOWCAST_GLYPH = "≈"


@dataclass(frozen=True)
class PredictionError:
    """How far a now-cast was from the report that came for its instant."""

    robot: str
    ahead_s: float  # wall seconds from its basis to the report
    position_m: float | None
    progress: float | None  # of the skill (1.0: the wrong skill)
    battery: float | None


class NowcastView:
    """The now-casts of the latest forecast, and the error of each robot's last one."""

    def __init__(self) -> None:
        self.errors: dict[str, PredictionError] = {}
        self._basis: dict[str, Telemetry] = {}  # the telemetry the forecast started from
        self._cached: tuple[object, dict[str, Nowcast | None]] = (None, {})

    def at(
        self, forecast: Forecast | None, mission: Mission | None, t: float, status: SimStatus | None
    ) -> dict[str, Nowcast | None]:
        """Each robot's probable state at wall time `t` (POSIX seconds)."""
        if forecast is None or mission is None:
            return {}
        key = (id(forecast), id(mission), round(t, 1))
        if self._cached[0] != key:
            self._cached = (key, self._walk(forecast, mission, t, status))
        return self._cached[1]

    def _walk(
        self, forecast: Forecast, mission: Mission, t: float, status: SimStatus | None
    ) -> dict[str, Nowcast | None]:
        speed = status.speed if status is not None and status.speed > 0 else 1.0
        link = link_of(status, forecast.now)
        links = {r: link for r in forecast.courses}
        return nowcasts(forecast.courses, mission, t, speed, links)

    def reported(
        self,
        forecast: Forecast | None,
        mission: Mission | None,
        telemetry: Mapping[str, Telemetry],
        status: SimStatus | None,
    ) -> None:
        """New telemetry came (before the forecast is recomputed): what the last
        forecast predicted for each new report's time, against it."""
        for robot, t in telemetry.items():
            old = self._basis.get(robot)
            self._basis[robot] = t
            if old is None or old is t or t.at <= old.at:
                continue
            nc = self.at(forecast, mission, t.at.timestamp(), status).get(robot)
            if nc is not None:
                self._compare(nc, t)

    def _compare(self, nc: Nowcast, t: Telemetry) -> None:
        err = PredictionError(
            robot=nc.robot,
            ahead_s=nc.age_s,
            position_m=_distance(nc, t),
            progress=_progress_error(nc, t),
            battery=abs(nc.battery - t.battery) if nc.battery is not None else None,
        )
        self.errors[nc.robot] = err
        log.info(
            "now-cast of %s, %.1f s ahead: %s m off, progress %s off, battery %s off",
            err.robot,
            err.ahead_s,
            _fmt(err.position_m),
            _fmt(err.progress),
            _fmt(err.battery),
        )


def _distance(nc: Nowcast, t: Telemetry) -> float | None:
    if nc.x is None or nc.y is None:
        return None
    return math.dist((nc.x, nc.y), (t.pose.x, t.pose.y))


def _progress_error(nc: Nowcast, t: Telemetry) -> float:
    if nc.skill != t.skill:
        return 1.0
    return abs((nc.progress or 0.0) - (t.progress or 0.0))


def _fmt(v: float | None) -> str:
    return "?" if v is None else f"{v:.2f}"


class Shown(Protocol):
    """What `robot_nowcast` reads of the console's model."""

    plan: Any
    mission: Mission | None
    clock: Any

    def freshness(self, robot: str) -> Any: ...


def robot_nowcast(model: Shown, robot: str) -> Nowcast | None:
    """The robot's now-cast when what the console knows of it is its last known
    state (stale: delayed, out of contact, silent); None otherwise."""
    if not model.freshness(robot).stale:
        return None
    plan = model.plan
    view: NowcastView = plan.nowcast
    return view.at(plan.forecast, model.mission, model.clock().timestamp(), plan.status).get(robot)


def battery_now(model: Shown, robot: str, heard: float) -> str:
    """'≈33%': the battery the now-cast puts the robot at now, where it differs
    from the one last heard ('' otherwise, or without a now-cast)."""
    nc = robot_nowcast(model, robot)
    now = f"{nc.battery:.0%}" if nc and nc.battery is not None else f"{heard:.0%}"
    return "" if now == f"{heard:.0%}" else f"{NOWCAST_GLYPH}{now}"


def probably_doing(model: Shown, robot: str) -> str | None:
    """'≈ lru1-5 62%' (a schedule header's room): the skill the robot probably
    executes now and how far (None when it probably executes none: what it
    was last seen doing says more)."""
    nc = robot_nowcast(model, robot)
    return f"{NOWCAST_GLYPH} {nc.skill} {nc.progress or 0:.0%}" if nc and nc.skill else None


def nowcast_words(nc: Nowcast) -> str:
    """'≈ now: lru1-5 62%, battery 33%' (what the robot probably does now)."""
    doing = f"{nc.skill} {nc.progress or 0:.0%}" if nc.skill else f"waiting ({nc.held})"
    battery = f", battery {nc.battery:.0%}" if nc.battery is not None else ""
    return f"{NOWCAST_GLYPH} now: {doing}{battery}"
