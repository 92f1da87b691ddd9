"""The operator's manual matches the world: the default library against the simulator.

The library (missions/libraries/mars.yaml) is what an operator plans with: its
figures (ranges, capacities, speeds, batteries, survey rates) must be the world's
(sim/calibration.py names any that drifted), its duration and energy models must
predict what the skill handlers do, and its defaults must work on the default world.
Each skill runs here in-process on a flat copy of the default world (no rocks nor sand:
the library models free ground), stepped by the sim clock, against the library's leg
for it (backend.core.plan.legs). No Zenoh, no wall-clock waits.
"""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import pytest

from backend.agent import Reply, SkillFailed, Success
from backend.core.library import Library
from backend.core.params import typed_params
from backend.core.plan.legs import build_leg, charge_s
from backend.files.missions import load_library, load_mission
from sim.calibration import SURVEY_ALTITUDE, drift, figures, properties
from sim.exchange import WorldExchange
from sim.fleet import SimFleet
from sim.skills.base import DRONE_MARGIN_S
from sim.skills.manipulation import APPROACH
from sim.skills.registry import RobotSkills
from sim.skills.science import CAMERA_RANGE, IDENTIFY_AT, IDENTIFY_S, IMAGING_S, PARTNER_WAIT
from sim.world import SimRobot, World
from sim.worldfile import WorldFile, load_world

from .conftest import MISSION, ROOT, WORLD

LIBRARY = ROOT / "missions" / "libraries" / "mars.yaml"
TYPES = {"lru1": "lru_science", "lru2": "lru_manipulator", "ardea": "drone", "lander": "lander"}
DT = 1.0  # sim seconds per skill step


@pytest.fixture(scope="module")
def library() -> Library:
    return load_library(LIBRARY)


@pytest.fixture(scope="module")
def spec() -> WorldFile:
    return load_world(WORLD)


def flat(spec: WorldFile) -> WorldFile:
    """The default world without rocks and sand: free ground, as the library models it."""
    out = spec.model_copy(deep=True)
    out.terrain.rock_fields.count = 0
    out.terrain.sand_patches.count = 0
    out.terrain.features = []
    return out


# ---------------------------------------------------------------- figures


def test_the_default_library_states_the_worlds_figures(library: Library, spec: WorldFile) -> None:
    assert drift(library, spec, World(spec).models) == []


def test_a_figure_that_drifted_is_named_with_the_worlds(library: Library, spec: WorldFile) -> None:
    """`missionctl sim` warns with these sentences; the test above fails on any."""
    lib = library.model_copy(deep=True)
    lru1 = lib.robot_types["lru_science"]
    assert lru1.battery is not None
    lru1.battery.per_metre = 0.001  # the library said "1 km per battery"
    lru1.properties["camera_range_m"] = 10
    del lib.robot_types["lru_manipulator"].properties["carry_stones"]
    lib.robot_types["drone"].survey_m2_per_s = 64
    found = drift(lib, spec, World(spec).models)
    assert found == [
        "robot_types.lru_science.properties.camera_range_m: 10; the world: 15",
        "robot_types.lru_science.battery.per_metre: 0.001; the world: 0.002857 (350 m per battery)",
        "robot_types.lru_manipulator.properties: missing carry_stones: 2 (the world's figures)",
        "robot_types.drone.survey_m2_per_s: 64; the world: 153.6..256 (lanes 64 m apart at "
        "10 m at 4 m/s)",
    ]


def test_the_simulated_robots_declare_the_librarys_figures(library: Library) -> None:
    mission, lib = load_mission(MISSION)
    fleet = SimFleet(mission, lib, load_world(WORLD), connect=["tcp/127.0.0.1:1"], speed=10)
    assert fleet.warnings == []
    for name, agent in fleet.agents.items():
        declared = agent.properties
        stated = library.robot_types[TYPES[name]].properties
        assert {k: declared[k] for k in stated} == stated, name
        assert declared == properties(fleet.world.spec, fleet.world.robots[name].model)
    assert fleet.agents["lru1"].properties["camera_range_m"] == CAMERA_RANGE
    assert fleet.agents["lru2"].properties["stone_reach_m"] == APPROACH
    assert fleet.agents["lru2"].properties["radio_range_m"] == 0


def test_the_descriptions_quote_the_worlds_figures(library: Library, spec: WorldFile) -> None:
    """What the console's skill picker and editor show (a skill's description, and each
    parameter's next to its field): the figures a newcomer would otherwise learn from
    failures."""
    models = World(spec).models
    lru1 = figures(spec, models["lru_science"])
    lru2 = figures(spec, models["lru_manipulator"])
    drone = figures(spec, models["drone"])
    lander = figures(spec, models["lander"])
    radii = sorted({r.radius for r in spec.rss})
    stones = sorted({r.stones for r in spec.rss})
    quoted = {
        "take_science_image": [f"{CAMERA_RANGE:g} m", f"{IMAGING_S:g} s"],
        "identify_stone": [
            f"{IDENTIFY_S:g} s",
            f"{radii[0]:g}-{radii[-1]:g} m in radius",
            f"{stones[0]}-{stones[-1]} stones",
            f"only {spec.scoring.min_score:g}",
            f"within {spec.scoring.collab_range:g} m",
            f"{PARTNER_WAIT:g} s",
            f"within {IDENTIFY_AT:g} m of the target",
        ],
        "pick_stone": [
            f"within {lru2['stone_reach_m']:g} m",
            f"{lru2['carry_stones']} stones, {lru2['carry_stones_in_box']} in the sample box",
        ],
        "drop_stone": [f"within {lander['shelf_reach_m']:g} m"],
        "pick_payload_box": [f"within {lander['shelf_reach_m']:g} m", "one box at a time"],
        "deploy_wifi_box": [
            f"covers {lru2['wifi_box_range_m']:g} m",
            f"lander covers {lander['comm_range_m']:g} m",
        ],
        "drive_to": [
            f"{spec.terrain.slow_factor * 100:g} % of the speed",
            f"{spec.terrain.slow_energy:g}x the energy",
        ],
        "fly_to": [f"{DRONE_MARGIN_S:g} s to spare"],
        "takeoff": [
            f"{drone['sensor_range_per_altitude_m']:g} m around",
            f"{drone['sensor_range_m']:g} m at most",
        ],
    }
    for skill, figs in quoted.items():
        sk = library.skills[skill]
        text = " ".join([sk.description, *(p.description for p in sk.params.values())])
        missing = [f for f in figs if f not in text]
        assert not missing, f"{skill}: {missing} not in {text!r}"
    assert f"sees {lru1['camera_range_m']:g} m" in library.robot_types["lru_science"].description
    assert f"{lru1['metres_per_battery']:g} m" in library.robot_types["lru_science"].description
    assert f"covers {lander['comm_range_m']:g} m" in library.robot_types["lander"].description
    assert f"at {SURVEY_ALTITUDE:g} m" in library.robot_types["drone"].description


# ---------------------------------------------------------------- skills against their models


class Ctx:
    paused = False

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(0)

    def progress(self, fraction: float, info: str = "", eta_s: float | None = None) -> None:
        pass

    async def ask_operator(self, text: str, choices: list[str], default: str, timeout: Any) -> Any:
        return Reply(default, False)  # nobody answers: the default


def host(world: World) -> Any:
    """A fleet stand-in whose asks and tells reach the other robots' world models."""

    async def ask(sender: SimRobot, target: str, topic: str, data: dict[str, Any]) -> Any:
        other = world.robots[target]
        if not world.can_talk(sender, other):
            return None
        return WorldExchange(world, other).asks()[topic](data, sender.name)

    async def tell(sender: SimRobot, target: str, topic: str, data: dict[str, Any]) -> bool:
        WorldExchange(world, world.robots[target]).tells()[topic](data, sender.name)
        return True

    return SimpleNamespace(
        world=world, dt=DT, robot_seconds=0.0, note=lambda r, t: None, ask=ask, tell=tell
    )


@dataclass
class Site:
    world: World
    host: Any
    library: Library
    robots: dict[str, SimRobot] = field(default_factory=dict)

    def params(self, skill: str, given: dict[str, Any]) -> dict[str, Any]:
        """The library's defaults under the given values (what the server sends)."""
        spec = self.library.skills[skill]
        return {**{k: p.default for k, p in spec.params.items() if p.default is not None}, **given}

    def handler_params(self, skill: str, given: dict[str, Any]) -> dict[str, Any]:
        """Those values typed by their kinds (what the robot SDK hands a handler)."""
        kinds = {k: p.type for k, p in self.library.skills[skill].params.items()}
        return typed_params(self.params(skill, given), kinds)

    async def call(self, robot: str, skill: str, given: dict[str, Any]) -> Success:
        r = self.robots[robot]
        fn = getattr(RobotSkills(self.host, r), skill)
        r.activity = skill
        try:
            result: Success = await fn(Ctx(), **self.handler_params(skill, given))
            return result
        finally:
            r.activity = None

    def run(self, robot: str, skill: str, **given: Any) -> Success:
        return asyncio.run(self.call(robot, skill, given))

    def predicted(self, robot: str, skill: str, given: dict[str, Any]) -> tuple[float, float]:
        """(robot seconds, battery used) the library predicts from where the robot is."""
        r = self.robots[robot]
        rt = self.library.robot_types[TYPES[robot]]
        spec = self.library.skills[skill]
        home = (self.world.spec.lander.x, self.world.spec.lander.y)
        leg = build_leg(rt, TYPES[robot], spec, self.params(skill, given), (r.x, r.y), home, None)
        return leg.busy_s + charge_s(rt, leg, r.battery - leg.energy), leg.energy


def site(library: Library, world_spec: WorldFile, seed: int = 1) -> Site:
    world = World(world_spec, seed=seed)
    s = Site(world, host(world), library)
    s.robots = {n: world.add_robot(n, t) for n, t in TYPES.items()}
    return s


@dataclass
class Case:
    robot: str
    skill: str
    params: dict[str, Any]
    at: tuple[float, float] | None = None  # where the robot starts it (else where it is)
    battery: float | None = None
    tolerance: float = 0.05  # relative, on time and energy
    energy: bool = True  # compare energy (not for charging, nor the lander)
    from_stone: float | None = None  # start this far from the stone it picks (m)


def _pose(x: float, y: float) -> dict[str, float]:
    return {"x": x, "y": y}


def _rect(x0: float, y0: float, x1: float, y1: float) -> list[dict[str, float]]:
    return [_pose(x0, y0), _pose(x1, y0), _pose(x1, y1), _pose(x0, y1)]


# one story on free ground, in order: each case starts where the one before left the world
STORY = [
    Case("lru1", "drive_to", {"goal": _pose(50.0, 0.0)}, at=(10.0, 0.0)),
    Case("lru1", "drive_to", {"goal": _pose(19.0, 23.0), "speed": 1.0}),
    Case("lru1", "take_science_image", {"target": _pose(29.0, 23.0)}),
    # the lanes' ends and turns: smaller areas map faster than the rate, larger slower
    Case("lru1", "explore", {"area": _rect(40, 30, 80, 70), "max_duration": 3600}, tolerance=0.15),
    Case("lru2", "identify_stone", {"target": _pose(-40.0, -30.0)}, at=(-40.0, -30.0)),
    Case("lru2", "identify_stone", {"target": _pose(29.0, 23.0)}, at=(-50.0, 23.0)),
    Case("lru2", "pick_stone", {"target": _pose(29.0, 23.0)}, from_stone=4.2),
    Case("lru2", "drive_to", {"goal": _pose(2.0, 0.0), "speed": 1.0}),
    Case("lru2", "drop_stone", {}),
    Case("lru2", "pick_payload_box", {"box": "sample_box"}),
    Case("lru2", "place_payload_box", {"box": "sample_box", "goal": _pose(24.0, 0.0)}),
    Case("lander", "load_box", {"box": "wifi_box_1", "slot": 2}, energy=False),
    Case("lru2", "deploy_wifi_box", {"goal": _pose(40.0, -40.0)}, at=(3.0, -2.0)),
    Case("lru2", "recharge", {}, battery=0.5, energy=False),
    Case("ardea", "takeoff", {}, at=(0.0, 0.0)),
    Case("ardea", "fly_to", {"goal": _pose(-150.0, -150.0)}),
    Case(
        "ardea", "explore", {"area": _rect(-160, -160, 40, 40), "max_duration": 600}, tolerance=0.1
    ),
    Case("ardea", "land", {}),
    Case("ardea", "recharge", {}, energy=False),
]


def test_each_skill_takes_the_time_and_battery_the_library_predicts(
    library: Library, spec: WorldFile
) -> None:
    s = site(library, flat(spec))
    off = []
    for case in STORY:
        r = s.robots[case.robot]
        if case.at is not None:
            r.x, r.y = case.at
        if case.battery is not None:
            r.battery = case.battery
        if case.from_stone is not None:  # the model's approach: 3 m at 0.3 m/s
            tx, ty = case.params["target"]["x"], case.params["target"]["y"]
            known = [k for k in s.world.stones.values() if k.state == "identified"]
            stone = min(known, key=lambda k: math.hypot(k.x - tx, k.y - ty))
            r.x, r.y = stone.x - case.from_stone, stone.y
        time_p, energy_p = s.predicted(case.robot, case.skill, case.params)
        t0, b0 = r.sim_seconds, r.battery
        s.run(case.robot, case.skill, **case.params)
        took, used = r.sim_seconds - t0, b0 - r.battery
        label = f"{case.robot} {case.skill}"
        if not math.isclose(time_p, took, rel_tol=case.tolerance, abs_tol=2 * DT):
            off.append(f"{label}: {took:.0f} s, the library says {time_p:.0f} s")
        if case.energy and not math.isclose(energy_p, used, rel_tol=case.tolerance):
            off.append(f"{label}: {used:.4f} of a battery, the library says {energy_p:.4f}")
    assert not off, "\n".join(off)


def test_the_survey_rates_hold_on_the_default_terrain(library: Library, spec: WorldFile) -> None:
    """Ardea maps the whole site in one flight at 10 m (the pilot study's 427 s); a
    rover maps the ground east of the lander, rocks and sand included."""
    s = site(library, spec)
    ardea = s.robots["ardea"]
    s.run("ardea", "takeoff")
    whole = {"area": _rect(-160, -160, 160, 160), "max_duration": 1000}
    predicted, _ = s.predicted("ardea", "explore", whole)
    t0 = ardea.sim_seconds
    s.run("ardea", "explore", **whole)
    assert ardea.sim_seconds - t0 == pytest.approx(predicted, rel=0.05)
    s = site(library, spec)  # nothing mapped yet
    lru1 = s.robots["lru1"]
    east = {"area": _rect(0, -49, 49, 49), "max_duration": 3600}
    predicted, _ = s.predicted("lru1", "explore", east)
    lru1.battery = 2.0  # a bigger battery: the survey, not the battery, ends it
    t0 = lru1.sim_seconds
    s.run("lru1", "explore", **east)
    assert lru1.sim_seconds - t0 == pytest.approx(predicted, rel=0.15)


@pytest.mark.parametrize("seed", range(1, 10))
def test_identify_and_pick_with_their_defaults_work_at_every_region(
    library: Library, spec: WorldFile, seed: int
) -> None:
    """Aimed at a region's centre, from afar or from nearby, identify (default search
    radius) finds a stone and pick reaches it (the default was 3 m: no stone at a
    region's centre; a rover identifying from 11 m away left the stone beyond its arm)."""
    s = site(library, spec, seed)
    lru2 = s.robots["lru2"]
    for rss in spec.rss:
        for dx, dy in ((-30.0, 0.0), (0.0, 11.0)):
            start = s.world.terrain.nearest_free(rss.x + dx, rss.y + dy, max_r=10.0)
            assert start is not None
            lru2.x, lru2.y = start
            lru2.battery, lru2.stones = 1.0, []
            centre = _pose(rss.x, rss.y)
            found = s.run("lru2", "identify_stone", target=centre)
            assert f"identified {rss.name}-s" in found.info, (rss.name, dx, dy)
            picked = s.run("lru2", "pick_stone", target=centre)
            assert picked.info.startswith("picked"), (rss.name, dx, dy, picked.info)


def test_a_drone_flight_the_library_plans_is_one_the_drone_flies(
    library: Library, spec: WorldFile
) -> None:
    """The library's figures for a whole-site survey fit one battery: the flight the
    pilot study's ideal operator plans (take off, survey, land) is not refused."""
    s = site(library, spec)
    steps = [
        ("takeoff", {}),
        ("explore", {"area": _rect(-160, -160, 160, 160), "max_duration": 560}),
        ("land", {}),
    ]
    used = 0.0
    ardea = s.robots["ardea"]
    for skill, given in steps:
        _, energy = s.predicted("ardea", skill, given)
        used += energy
        try:
            s.run("ardea", skill, **given)
        except SkillFailed as e:  # pragma: no cover - the message says why
            pytest.fail(f"{skill}: {e.reason}")
    rt = library.robot_types["drone"]
    assert rt.battery is not None
    assert used < 1.0 - rt.battery.reserve
    assert 1.0 - ardea.battery == pytest.approx(used, rel=0.05)
