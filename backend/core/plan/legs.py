"""One skill, from where it starts: its travel, time, energy and where it ends.

The library's models say it (`DurationModel`, `EnergyModel`, the robot
type's `speed_mps`, `flies` and `battery`); the site map, when known, gives
route lengths and comms coverage. Charging depends on the battery on
arrival, so a leg only says the level it charges to (`charge_to`); the
course (backend.core.plan.course) adds the time it takes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from backend.core.library import BatteryModel, RobotType, SkillSpec, default_value
from backend.core.plan.geometry import (
    Point,
    along,
    centroid,
    distance,
    point_of,
    polygon_of,
    samples,
    to_polygon,
)
from backend.core.plan.geometry import area as polygon_area
from backend.core.plan.inputs import SiteMap

COVERAGE_STEP_M = 4.0  # metres between the points of a path asked about coverage
NO_BATTERY = BatteryModel(reserve=0.0, margin=0.0)

Span = tuple[float, float]  # fractions (0..1) of a phase


@dataclass(frozen=True, slots=True)
class Leg:
    travel_m: float  # metres travelled (0: none, or from an unknown place)
    travel_s: float  # robot seconds travelling
    work_s: float  # robot seconds of the rest, charging aside
    goal: Point | None  # where the travel ends (None: no travel)
    end: Point | None  # where the robot is afterwards (None: unknown)
    no_route: bool  # the map knows no route to the goal
    charge_to: float | None  # the battery level it charges to, after travelling
    per_s: float  # battery use per robot second (travel and work)
    per_metre: float  # battery use per metre travelled
    travel_out: tuple[Span, ...]  # parts of the travel out of comms coverage
    work_out: bool  # where it works is (partly) out of comms coverage
    area: tuple[Point, ...] | None  # the area it works in

    @property
    def busy_s(self) -> float:
        """Robot seconds of travel and work (charging aside)."""
        return self.travel_s + self.work_s

    @property
    def energy(self) -> float:
        """Battery it uses travelling and working (charging aside)."""
        return self.per_s * self.busy_s + self.per_metre * self.travel_m


def _number(v: Any) -> float | None:
    return float(v) if isinstance(v, int | float) and not isinstance(v, bool) else None


def _param(spec: SkillSpec, params: dict[str, Any], name: str) -> Any:
    """A parameter's value, else what the server would fill in (a mission file
    fills defaults in; a skill built by hand may not have)."""
    if name in params:
        return params[name]
    p = spec.params.get(name)
    return default_value(p) if p is not None else None


def _goal(spec: SkillSpec, params: dict[str, Any], home: Point | None) -> Point | None:
    d = spec.duration
    if d.goes_home(params):
        return home
    return point_of(params.get(d.goal_param)) if d.goal_param else None


def _travel(
    rt: RobotType, start: Point | None, goal: Point | None, site: SiteMap | None
) -> tuple[float, bool]:
    """(metres, no route) from start to goal: the map's route for a rover,
    else a straight line; 0 when either end is unknown."""
    if start is None or goal is None:
        return 0.0, False
    straight = distance(start, goal)
    if site is None or rt.flies or straight < 1e-6:
        return straight, False
    metres = site.route_length(start, goal)
    if math.isinf(metres):
        return straight, True
    return metres, False


def _work_s(spec: SkillSpec, params: dict[str, Any]) -> float:
    total = spec.duration.base_s
    for name, factor in spec.duration.per_param_s.items():
        v = _number(_param(spec, params, name))
        if v is not None:
            total += factor * v
    return total


def _travel_s(spec: SkillSpec, rt: RobotType, params: dict[str, Any], metres: float) -> float:
    d = spec.duration
    speed = _number(_param(spec, params, d.speed_param)) if d.speed_param else None
    if speed is None or speed <= 0:
        speed = rt.speed_mps
    if speed is not None and speed > 0:
        return metres / speed
    return d.per_metre_s * metres


def _coverage(
    site: SiteMap | None,
    start: Point | None,
    goal: Point | None,
    place: Point | None,
    area: tuple[Point, ...] | None,
) -> tuple[tuple[Span, ...], bool]:
    """Out-of-coverage parts of the travel, and whether the place of work is out."""
    if site is None:
        return (), False
    spans = _out_spans(site, start, goal) if start is not None and goal is not None else ()
    where = samples(area) if area is not None else ([place] if place is not None else [])
    return spans, any(site.covered(x, y) is False for x, y in where)


def _out_spans(site: SiteMap, start: Point, goal: Point) -> tuple[Span, ...]:
    """The runs of the path start -> goal out of coverage, as fractions of it."""
    spans: list[Span] = []
    run: float | None = None  # where the run out of coverage began
    for f, (x, y) in along(start, goal, COVERAGE_STEP_M):
        out = site.covered(x, y) is False
        if out and run is None:
            run = f
        elif not out and run is not None:
            spans.append((run, f))
            run = None
    if run is not None:
        spans.append((run, 1.0))
    return tuple(spans)


def _end(start: Point | None, goal: Point | None, area: tuple[Point, ...] | None) -> Point | None:
    """Where the robot is when the skill is done: its goal, else the middle
    of the area it works in, else where it started."""
    if goal is not None:
        return goal
    return centroid(area) if area is not None else start


def _charge_to(spec: SkillSpec, params: dict[str, Any]) -> float | None:
    """The battery level (0..1) a charging skill stops at, if it names one."""
    name = spec.duration.charge_param
    level = _number(_param(spec, params, name)) if name else None
    return None if level is None else min(1.0, max(0.0, level))


def _survey_s(rt: RobotType, start: Point | None, area: tuple[Point, ...], rate: float) -> float:
    """Robot seconds to reach an area and map all of it at `rate` m2/s."""
    reach = to_polygon(start, area) / (rt.speed_mps or 1.0) if start is not None else 0.0
    return reach + polygon_area(area) / rate


def build_leg(
    rt: RobotType,
    robot_type: str,
    spec: SkillSpec,
    params: dict[str, Any],
    start: Point | None,
    home: Point | None,
    site: SiteMap | None,
) -> Leg:
    d = spec.duration
    goal = _goal(spec, params, home)
    metres, no_route = _travel(rt, start, goal, site)
    area = polygon_of(params.get(d.area_param)) if d.area_param else None
    end = _end(start, goal, area)
    per_s, per_metre = spec.energy.rates(robot_type, rt.battery or NO_BATTERY)
    work_s = _work_s(spec, params)
    if area is not None and rt.survey_m2_per_s:  # done once mapped, if sooner
        work_s = min(work_s, _survey_s(rt, start, area, rt.survey_m2_per_s))
    travel_out, work_out = _coverage(site, start if goal is not None else None, goal, end, area)
    return Leg(
        travel_m=metres,
        travel_s=_travel_s(spec, rt, params, metres),
        work_s=work_s,
        goal=goal,
        end=end,
        no_route=no_route,
        charge_to=_charge_to(spec, params),
        per_s=per_s,
        per_metre=per_metre,
        travel_out=travel_out,
        work_out=work_out,
        area=area,
    )


def charge_s(rt: RobotType, leg: Leg, battery: float) -> float:
    """Robot seconds charging from `battery` (on arrival) to the leg's level."""
    rate = rt.battery.charge_per_s if rt.battery is not None else 0.0
    if leg.charge_to is None or rate <= 0 or battery >= leg.charge_to:
        return 0.0
    return (leg.charge_to - battery) / rate
