"""The figures an operator plans with, as the simulated world has them: one source.

The world file (`missions/worlds/*.yaml`: robot models, comms, the lander) and the
skill handlers' constants (`sim/skills/*`) make the simulated world. From them:

- `properties`: what a simulated robot declares in its manifest (ranges,
  capacities, battery), so `ctl robots` and the console's fleet screen tell them;
- `figures`: the part of those a skill library states per robot type
  (`robot_types.<type>.properties`);
- `drift`: where a library (the operator's manual) says otherwise, about those
  figures, speeds, survey rates, batteries and radio range. `missionctl sim`
  warns about each difference; tests/sim/test_calibration.py fails on one in the
  default library, and also runs every skill handler against the library's
  duration and energy models.
"""

from __future__ import annotations

import math
from typing import Any

from backend.core.library import Library, PropertyValue, RobotType
from sim.skills.base import DRONE_RANGE_ALTITUDE, drone_range
from sim.skills.manipulation import APPROACH, LANDER_REACH
from sim.skills.mobility import LANE_SPACING
from sim.skills.science import CAMERA_RANGE
from sim.worldfile import RobotModel, WorldFile

REL_TOL = 0.01  # a library's rounded decimals (0.002857 for 1/350) are the same figure
# The sim's lanes turn and overlap, and rovers slow down on sand: an explore maps less
# than lane spacing x speed. A library's survey rate is right between these shares of it.
SURVEY_SHARE = (0.6, 1.0)
SURVEY_ALTITUDE = 10.0  # m: the altitude a drone's survey rate is stated for (takeoff's default)


def figures(world: WorldFile, model: RobotModel) -> dict[str, PropertyValue]:
    """What an operator plans with about a robot of this model: ranges, capacities,
    battery. Units are in the names."""
    if model.kind == "static":
        lander = world.lander
        return {
            "comm_range_m": lander.comm_radius,
            "pad_radius_m": lander.pad_radius,
            "shelf_reach_m": lander.pad_radius + LANDER_REACH,
            "shelf_slots": lander.shelf_slots,
        }
    out: dict[str, PropertyValue] = {"max_speed_mps": model.max_speed}
    if model.kind == "drone":
        out["sensor_range_m"] = drone_range(model, SURVEY_ALTITUDE)
        out["sensor_range_per_altitude_m"] = model.sensor_range / DRONE_RANGE_ALTITUDE
        out["flight_s_per_battery"] = model.flight_s_per_battery
        return out
    out["sensor_range_m"] = model.sensor_range
    out["metres_per_battery"] = model.metres_per_battery
    if "science_camera" in model.capabilities:
        out["camera_range_m"] = CAMERA_RANGE
    if "manipulator" in model.capabilities:
        out["stone_reach_m"] = APPROACH
        out["carry_stones"] = model.carry_stones
        out["carry_stones_in_box"] = model.carry_stones_in_box
        out["carry_boxes"] = 1  # one payload box at a time (the sample box too)
        out["wifi_box_range_m"] = world.comms.wifi_range
    return out


def properties(world: WorldFile, model: RobotModel) -> dict[str, Any]:
    """A simulated robot's manifest properties."""
    out: dict[str, Any] = {
        "simulated": True,
        "kind": model.kind,
        "capabilities": list(model.capabilities),
    }
    out.update(figures(world, model))
    if model.kind != "static":
        out["radio_range_m"] = world.comms.direct_range
    return out


def _differs(stated: float, truth: float) -> bool:
    return not math.isclose(stated, truth, rel_tol=REL_TOL, abs_tol=1e-9)


def _same(stated: PropertyValue, value: PropertyValue) -> bool:
    numbers = (int, float)
    if isinstance(stated, numbers) and isinstance(value, numbers):
        return isinstance(stated, bool) == isinstance(value, bool) and not _differs(stated, value)
    return stated == value


def _g(x: float) -> str:
    return f"{x:.4g}"


def _show(v: PropertyValue) -> str:
    return _g(v) if isinstance(v, float) else str(v)


def _battery(where: str, rt: RobotType, m: RobotModel) -> list[str]:
    b = rt.battery
    if b is None:
        return [f"{where}.battery: none; the world's {m.kind} has one"]
    if m.kind == "drone":
        truth = {
            "per_s": (1.0 / m.flight_s_per_battery, f"{_g(m.flight_s_per_battery)} s of flight"),
            "per_metre": (0.0, "a drone pays by the second"),
        }
    else:
        truth = {
            "per_s": (m.work_per_hour / 3600.0, f"{_g(m.work_per_hour)} battery per hour of work"),
            "per_metre": (1.0 / m.metres_per_battery, f"{_g(m.metres_per_battery)} m per battery"),
        }
    truth["charge_per_s"] = (m.charge_per_minute / 60.0, f"{_g(m.charge_per_minute)} a minute")
    truth["reserve"] = (m.reserve, "the level it stops at")
    out = []
    for name, (value, why) in truth.items():
        stated = getattr(b, name)
        if _differs(stated, value):
            out.append(f"{where}.battery.{name}: {_g(stated)}; the world: {_g(value)} ({why})")
    return out


def _survey(where: str, rt: RobotType, m: RobotModel) -> list[str]:
    rng = drone_range(m, SURVEY_ALTITUDE) if m.kind == "drone" else m.sensor_range
    ideal = LANE_SPACING * rng * m.speed
    low, high = SURVEY_SHARE[0] * ideal, SURVEY_SHARE[1] * ideal
    stated = rt.survey_m2_per_s
    if stated is not None and low <= stated <= high:
        return []
    at = f" at {SURVEY_ALTITUDE:g} m" if m.kind == "drone" else ""
    said = "none" if stated is None else _g(stated)
    return [
        f"{where}.survey_m2_per_s: {said}; the world: {_g(low)}..{_g(high)} (lanes "
        f"{_g(LANE_SPACING * rng)} m apart{at} at {_g(m.speed)} m/s)"
    ]


def _robot_type(world: WorldFile, name: str, rt: RobotType, m: RobotModel) -> list[str]:
    where = f"robot_types.{name}"
    out = _properties(where, rt.properties, figures(world, m))
    if m.kind == "static":
        return out
    return out + _motion(world, where, name, rt, m) + _survey(where, rt, m) + _battery(where, rt, m)


def _properties(
    where: str, stated: dict[str, PropertyValue], truth: dict[str, PropertyValue]
) -> list[str]:
    """The type's properties against the world's figures: missing, differing, unknown."""
    out = []
    missing = [f"{k}: {_show(v)}" for k, v in truth.items() if k not in stated]
    if missing:
        out.append(f"{where}.properties: missing {', '.join(missing)} (the world's figures)")
    for key, value in truth.items():
        if key in stated and not _same(stated[key], value):
            out.append(f"{where}.properties.{key}: {_show(stated[key])}; the world: {_show(value)}")
    for key in sorted(set(stated) - set(truth)):
        out.append(f"{where}.properties.{key}: {_show(stated[key])}; the world has no such figure")
    return out


def _motion(world: WorldFile, where: str, name: str, rt: RobotType, m: RobotModel) -> list[str]:
    """A mobile robot's speed, whether it flies and its radio's range."""
    out = []
    if rt.speed_mps is None or _differs(rt.speed_mps, m.speed):
        said = "none" if rt.speed_mps is None else _g(rt.speed_mps)
        out.append(f"{where}.speed_mps: {said}; the world: {_g(m.speed)}")
    if rt.flies != (m.kind == "drone"):
        out.append(f"{where}.flies: {rt.flies}; the world's {name} is a {m.kind}")
    if _differs(rt.radio_range_m, world.comms.direct_range):
        out.append(
            f"{where}.radio_range_m: {_g(rt.radio_range_m)}; the world: "
            f"{_g(world.comms.direct_range)} (comms.direct_range)"
        )
    return out


def drift(library: Library, world: WorldFile, models: dict[str, RobotModel]) -> list[str]:
    """Where the library's figures differ from the world's, one sentence each, for the
    robot types both know (`models`: the world's, defaults included)."""
    out: list[str] = []
    for name, rt in library.robot_types.items():
        m = models.get(name)
        if m is not None:
            out += _robot_type(world, name, rt, m)
    return out
