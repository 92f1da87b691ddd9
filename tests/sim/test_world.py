"""Pure tests of the simulated world, its skills and the map-feed codec (no Zenoh)."""

from __future__ import annotations

import asyncio
import inspect
import math
import re
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from backend.agent import Reply, SkillFailed
from backend.agent.registration import Handler, handler_differences
from backend.core.model import Pose, Position
from backend.core.params import typed_params
from backend.files.diagnostics import FileProblems
from backend.files.missions import load_library, load_mission
from backend.protocol import mapfeed as mf
from sim.exchange import WorldExchange
from sim.fleet import SimFleet
from sim.pathing import ROCK, Follower, lawnmower, segment_cells
from sim.skills import science
from sim.skills.registry import RobotSkills
from sim.world import World
from sim.worldfile import load_world, parse_world

from .conftest import LIBRARY_FILE, MISSION, WORLD

LIBRARY = load_library(LIBRARY_FILE)


@pytest.fixture(scope="module")
def spec():
    return load_world(WORLD)


@pytest.fixture
def world(spec) -> World:
    return World(spec, seed=1)


# ---------------------------------------------------------------- world file


def test_default_world_is_valid_and_deterministic(spec) -> None:
    a, b, c = World(spec, seed=1), World(spec, seed=1), World(spec, seed=2)
    assert np.array_equal(a.terrain.grid, b.terrain.grid)
    assert [(s.id, s.x, s.y) for s in a.stones.values()] == [
        (s.id, s.x, s.y) for s in b.stones.values()
    ]
    assert not np.array_equal(a.terrain.grid, c.terrain.grid)
    assert [(s.x, s.y) for s in a.stones.values()] != [(s.x, s.y) for s in c.stones.values()]
    # a few hundred metres, some slow and some impassable ground
    assert a.geom.x1 - a.geom.x0 >= 200
    counts = np.bincount(a.terrain.grid.ravel(), minlength=4)
    assert counts[mf.T_SLOW] > 0 and counts[mf.T_ROCK] > 0
    assert counts[mf.T_UNKNOWN] == 0  # the truth knows every cell


def test_pilot_scenario_layout(world: World) -> None:
    """The calibrated pilot study (docs/pilot-study.md): poor regions near the lander,
    inside its coverage (one where the orbital hint POI-A points); the two most valuable
    far away in the bottom right, out of coverage; few stones everywhere."""
    rss_a = world.rss_near(29.0, 23.0, 3.0)  # POI-A
    assert rss_a is not None and rss_a.name == "RSS-A" and rss_a.max_score <= 0.5
    near = [r for r in world.rss.values() if world.link_quality(r.x, r.y) > 0]
    assert {r.name for r in near} == {"RSS-A", "RSS-B"}
    assert sum(r.max_score * len(r.stones) for r in near) < 1.8  # all of them: not the best
    best = sorted(world.rss.values(), key=lambda r: -r.max_score)[:2]
    assert [r.max_score for r in best] == [1.0, 0.9] and sum(r.max_score for r in best) >= 1.8
    for r in best:
        assert r.x > 50 and r.y < -30 and math.hypot(r.x, r.y) > 90  # bottom right, far
        assert world.link_quality(r.x, r.y) == 0  # beyond coverage: a Wi-Fi box is needed
    assert all(len(r.stones) <= 3 for r in world.rss.values())
    assert world.spec.comms.direct_range == 0  # robots talk through the network only
    # every RSS and stone is reachable by a rover
    for stone in world.stones.values():
        assert world.terrain.at(stone.x, stone.y) != ROCK


def test_world_file_errors_point_at_line_and_field(tmp_path: Path) -> None:
    text = (
        "format: missionctl/world@1\n"
        "name: broken\n"
        "rss:\n"
        "  - {name: RSS-A, x: 10, y: 10, radius: 5, max_score: -1}\n"
        "  - {name: RSS-A, x: 900, y: 10, max_score: 1}\n"
        "boxes:\n"
        "  sample_box: {kind: sample, at: shelf}\n"
    )
    with pytest.raises(FileProblems) as exc:
        parse_world(text, "w.yaml")
    lines = [str(i) for i in exc.value.issues]
    assert any(ln.startswith("w.yaml:4:") and "rss[0].max_score" in ln for ln in lines), lines
    assert any(
        ln.startswith("w.yaml:7:") and "boxes.sample_box" in ln and "slot" in ln for ln in lines
    ), lines
    # semantic checks run on a structurally valid file
    ok = text.replace("max_score: -1", "max_score: 1").replace("at: shelf}", "at: shelf, slot: 1}")
    with pytest.raises(FileProblems) as exc:
        parse_world(ok, "w.yaml")
    lines = [str(i) for i in exc.value.issues]
    assert any(
        ln.startswith("w.yaml:5:") and "duplicate region name 'RSS-A'" in ln for ln in lines
    ), lines
    assert any("outside the site" in ln for ln in lines), lines
    bad_yaml = tmp_path / "bad.yaml"
    bad_yaml.write_text("format: [\n")
    with pytest.raises(FileProblems) as exc:
        load_world(bad_yaml)
    assert str(exc.value.issues[0]).startswith(f"{bad_yaml}:")


# ------------------------------------------------------------ coverage, exploration, ground view


def test_coverage_grows_with_a_wifi_box_inside_coverage_only(world: World) -> None:
    before = float((world.coverage > 0).mean())
    assert world.link_quality(85.0, 0.0) == 0
    far = world.boxes["wifi_box_2"]
    far.where, far.x, far.y, far.on = "ground", 150.0, 150.0, True
    world.recompute_coverage()
    assert float((world.coverage > 0).mean()) == pytest.approx(before)  # nothing relays it
    box = world.boxes["wifi_box_1"]
    box.where, box.x, box.y, box.on = "ground", 50.0, 0.0, True
    world.recompute_coverage()
    after = float((world.coverage > 0).mean())
    assert after > before
    assert world.link_quality(85.0, 0.0) > 0
    # a chain: a box inside the extended coverage relays further
    far.x, far.y = 92.0, 0.0
    world.recompute_coverage()
    assert world.link_quality(130.0, 0.0) > 0


def test_exploration_reveals_rss_and_reaches_the_ground_only_in_range(spec) -> None:
    radio = spec.model_copy(update={"comms": spec.comms.model_copy(update={"direct_range": 30})})
    world = World(radio, seed=1)  # robots with a direct radio besides the network
    near = world.add_robot("lru1", "lru_science")
    near.x, near.y = 29.0, 25.0  # at RSS-A, inside coverage
    far = world.add_robot("ardea", "drone")
    far.x, far.y, far.airborne = -32.0, 80.0, True  # over RSS-C, out of coverage
    assert world.in_range(near) and not world.in_range(far)
    assert not world.can_talk(near, far)  # no coverage out there, and too far for direct radio
    for r in (near, far):
        assert world.reveal(r, 10.0) > 0
    assert world.discover(near, 10.0) == ["RSS-A"]
    assert world.discover(far, 10.0) == ["RSS-C"]
    assert "RSS-A" in near.knowledge.rss and "RSS-C" not in near.knowledge.rss
    assert world.pump_downlink(now=0.0, delay=0.0)
    assert set(world.ground.rss) == {"RSS-A"}  # RSS-C waits aboard ardea
    i, j = world.geom.cell_of(-32.0, 80.0)
    assert world.explored[i, j] and not world.ground.explored[i, j]
    far.x, far.y = -20.0, 85.0
    near.x, near.y = -20.0, 72.0  # out of coverage too, but 13 m apart: direct radio
    assert not world.in_range(near) and world.can_talk(near, far)
    near.x, near.y = 29.0, 25.0
    far.x, far.y = 5.0, 5.0  # back in coverage
    world.pump_downlink(now=1.0, delay=2.0)  # on its way: a 2 s link delay
    assert "RSS-C" not in world.ground.rss
    world.pump_downlink(now=3.5, delay=2.0)
    assert set(world.ground.rss) == {"RSS-A", "RSS-C"}
    assert world.ground.explored[i, j]
    layers = world.ground.layers(world.terrain.grid, world.coverage)
    assert layers["terrain"][i, j] == world.terrain.grid[i, j]  # the codes are the feed's
    assert layers["terrain"][world.geom.cell_of(-150.0, -150.0)] == mf.T_UNKNOWN


def test_path_avoids_impassable_cells(world: World) -> None:
    rover = world.add_robot("lru1", "lru_science")
    start = world.terrain.nearest_free(45.0, 38.0)
    goal = world.terrain.nearest_free(80.0, 38.0)
    assert start and goal
    rover.x, rover.y = start
    route = world.terrain.route(start, goal, flies=False)
    assert not world.terrain.straight_clear(start, goal)  # the crater lies between
    for a, b in zip(route, route[1:], strict=False):
        rows, cols = segment_cells(world.geom, a[0], a[1], b[0], b[1])
        assert (world.terrain.grid[rows, cols] != ROCK).all()
    f = Follower(route)
    assert f.total > math.dist(start, goal) + 5
    with pytest.raises(Exception, match="impassable"):
        world.terrain.route((rover.x, rover.y), (62.0, 38.0), flies=False)  # the crater floor


def test_lawnmower_covers_the_polygon() -> None:
    poly = [(30.0, 0.0), (80.0, 0.0), (80.0, 40.0), (30.0, 40.0)]
    pts = lawnmower(poly, spacing=16.0, start=(42.0, 18.0))
    assert len(pts) == 6
    assert all(30 <= x <= 80 and 0 <= y <= 40 for x, y in pts)


# ---------------------------------------------------------------- skills without Zenoh


class FakeCtx:
    def __init__(self, replies: list[str] | None = None) -> None:
        self.paused = False
        self.progress_calls: list[tuple[float, str, float | None]] = []
        self.replies = list(replies or [])  # the operators' answers; none left: the default
        self.asked: list[tuple[str, list[str], str, float | str]] = []

    async def ask_operator(self, text, choices, default, timeout) -> Reply:
        self.asked.append((text, list(choices), default, timeout))
        if self.replies:
            return Reply(self.replies.pop(0), True, "ann@console")
        return Reply(default, False)

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(0)

    def progress(self, fraction: float, info: str = "", eta_s: float | None = None) -> None:
        assert 0.0 <= fraction <= 1.0
        self.progress_calls.append((fraction, info, eta_s))


def fake_fleet(world: World) -> Any:
    async def ask(sender, target, topic, data):
        return None

    async def tell(sender, target, topic, data):
        return False

    return SimpleNamespace(
        world=world, dt=5.0, robot_seconds=0.0, note=lambda r, t: None, ask=ask, tell=tell
    )


def run(coro) -> Any:
    return asyncio.run(coro)


def call(skills: RobotSkills, skill: str, ctx: Any = None, **given: Any) -> Any:
    """Run a handler as the agent calls it: every parameter, those not given
    with the library's defaults (the server's fill-in), typed by their kind."""
    spec = LIBRARY.skills[skill]
    params = {**typed_params(spec.signature().defaults, spec.kinds()), **given}
    return run(getattr(skills, skill)(ctx if ctx is not None else FakeCtx(), **params))


def test_every_simulated_handler_fits_the_library_and_the_fleet_keeps_its_signature(
    spec,
) -> None:
    """No handler declares a default of its own (the server fills the library's
    in) nor takes **params: the check the agent makes at registration finds
    nothing, through the fleet's wrapper too."""
    mission, library = load_mission(MISSION)
    fleet = SimFleet(mission, library, spec, connect=["tcp/127.0.0.1:1"])
    for name, robot in fleet.world.robots.items():
        for skill, fn in RobotSkills(fleet, robot).handlers().items():
            if skill not in library.skills_of(robot.type):
                continue
            wrapped = fleet._wrap(robot, skill, fn)
            assert inspect.signature(wrapped) == inspect.signature(fn)
            handler = Handler(wrapped, "1.0.0", raw=False)
            sig = library.skills[skill].signature()
            assert handler_differences(name, skill, handler, sig) == []


def test_battery_drains_with_distance_and_an_empty_battery_fails_with_the_distance(
    world: World,
) -> None:
    rover = world.add_robot("lru1", "lru_science")
    rover.x, rover.y, rover.battery = 4.0, 3.0, 1.0
    skills = RobotSkills(fake_fleet(world), rover)
    ctx = FakeCtx()
    call(skills, "drive_to", ctx, goal=Pose(x=40.0, y=3.0), speed=0.5)
    used = 1.0 - rover.battery
    assert math.hypot(rover.x - 40.0, rover.y - 3.0) <= 0.5
    per_m = 1 / rover.model.metres_per_battery
    assert 35 * per_m <= used <= 45 * per_m  # 350 m per battery, plus electronics
    assert (
        ctx.progress_calls[-1][0] == 1.0 and ctx.progress_calls[len(ctx.progress_calls) // 2][2] > 0
    )
    rover.x, rover.y = 20.0, 3.0
    rover.battery = 0.13  # 8 % above the reserve: about 28 m, past the lander
    with pytest.raises(SkillFailed) as exc:
        call(skills, "drive_to", goal=Pose(x=-45.0, y=3.0))
    m = re.search(r"battery empty after (\d+) m of (\d+) m", exc.value.reason)
    assert m and "recharge at the lander" in exc.value.reason, exc.value.reason
    done, total = int(m.group(1)), int(m.group(2))
    assert 20 <= done <= 32 and total > 45
    assert rover.battery == pytest.approx(rover.model.reserve)
    # recharging uses the reserve to get home, then charges
    call(skills, "recharge", target_level=0.9)
    assert world.at_lander(rover) and rover.battery >= 0.9


def test_drone_refuses_a_flight_longer_than_its_battery_and_recharges_on_the_pad(
    world: World,
) -> None:
    drone = world.add_robot("ardea", "drone")
    drone.x, drone.y, drone.battery = -2.0, 2.0, 0.3
    skills = RobotSkills(fake_fleet(world), drone)
    with pytest.raises(SkillFailed, match="take off first"):
        call(skills, "fly_to", goal=Pose(x=20.0, y=0.0))
    call(skills, "takeoff", altitude=5.0)
    assert drone.airborne and drone.z == 5.0
    with pytest.raises(SkillFailed) as exc:
        call(skills, "fly_to", goal=Pose(x=150.0, y=-150.0))
    assert "refused before the flight" in exc.value.reason
    assert drone.airborne and math.hypot(drone.x + 2, drone.y - 2) < 1  # it did not move
    call(skills, "fly_to", goal=Pose(x=30.0, y=0.0))
    assert drone.battery < 0.3
    call(skills, "land", where="lander_pad")
    assert not drone.airborne and world.docked(drone)
    low = drone.battery
    drone.charge(60.0)
    assert drone.battery == pytest.approx(low + drone.model.charge_per_minute)


def test_outcomes_hardly_depend_on_the_step_size(spec) -> None:
    """The sim speed only changes the step: a survey ends at (nearly) the same place."""
    ends = []
    for dt in (0.25, 5.0):
        world = World(spec, seed=1)
        rover = world.add_robot("lru1", "lru_science")
        fleet = fake_fleet(world)
        fleet.dt = dt
        skills = RobotSkills(fleet, rover)
        call(skills, "drive_to", goal=Pose(x=42.0, y=18.0))
        t0 = rover.sim_seconds
        area = [
            Position(x=30, y=0),
            Position(x=80, y=0),
            Position(x=80, y=40),
            Position(x=30, y=40),
        ]
        call(skills, "explore", area=area, max_duration=150)
        assert rover.sim_seconds - t0 == pytest.approx(150.0)
        ends.append((rover.x, rover.y, int(world.explored.sum()), rover.battery))
    (x1, y1, c1, b1), (x2, y2, c2, b2) = ends
    assert math.hypot(x1 - x2, y1 - y2) < 2.5
    assert abs(c1 - c2) <= 0.02 * c1 and abs(b1 - b2) < 0.002


def test_identify_alone_gives_the_minimum_and_together_the_top_score(world: World) -> None:
    lru1 = world.add_robot("lru1", "lru_science")
    lru2 = world.add_robot("lru2", "lru_manipulator")
    lru1.x, lru1.y = 29.0, 23.0
    lru2.x, lru2.y = 30.0, 23.0
    fleet = fake_fleet(world)
    s1, s2 = RobotSkills(fleet, lru1), RobotSkills(fleet, lru2)
    at = Position(x=29.0, y=23.0)
    call(s2, "identify_stone", target=at, search_radius=6.0)
    alone = [s for s in world.stones.values() if s.state == "identified"]
    assert [s.score for s in alone] == [0.1]
    lru2.activity = "identify_stone"  # the partner works on it at the same time (a barrier)
    lru1.activity = "identify_stone"
    call(s1, "identify_stone", target=at, search_radius=6.0, partner="lru2")
    top = [s for s in world.stones.values() if s.state == "identified" and s.score == 0.5]
    assert len(top) == 1 and top[0].identified_by == ("lru1", "lru2")
    with pytest.raises(SkillFailed, match="no region ideal for sampling stones"):
        call(s1, "identify_stone", target=Position(x=-10.0, y=-10.0))


def test_science_image_reveals_the_top_score(world: World) -> None:
    lru1 = world.add_robot("lru1", "lru_science")
    lru1.x, lru1.y = 22.0, 20.0
    call(RobotSkills(fake_fleet(world), lru1), "take_science_image", target=Pose(x=29.0, y=23.0))
    assert lru1.knowledge.rss["RSS-A"]["top_score"] == 0.5
    world.pump_downlink(0.0, 0.0)
    assert world.ground.rss["RSS-A"].top_score == 0.5


def exchanging_fleet(world: World) -> Any:
    """A host whose asks and tells reach the other robot's world model (sim/exchange.py)."""

    async def ask(sender, target, topic, data):
        return WorldExchange(world, world.robots[target]).asks()[topic](data, sender.name)

    async def tell(sender, target, topic, data):
        WorldExchange(world, world.robots[target]).tells()[topic](data, sender.name)
        return True

    return SimpleNamespace(
        world=world, dt=5.0, robot_seconds=0.0, note=lambda r, t: None, ask=ask, tell=tell
    )


def test_a_revealed_top_score_stays_when_another_robot_discovers_the_region(world: World) -> None:
    lru1 = world.add_robot("lru1", "lru_science")
    lru2 = world.add_robot("lru2", "lru_manipulator")
    lru1.x, lru1.y = 22.0, 20.0
    call(RobotSkills(fake_fleet(world), lru1), "take_science_image", target=Pose(x=29, y=23))
    world.pump_downlink(0.0, 0.0)
    assert world.ground.rss["RSS-A"].top_score == 0.5
    WorldExchange(world, lru2).tell_rss(lru1.knowledge.rss["RSS-A"], "lru1")
    lru2.x, lru2.y = 29.0, 23.0
    assert world.discover(lru2, 10.0) == ["RSS-A"]  # a later report, without the top score
    world.pump_downlink(1.0, 0.0)
    assert world.ground.rss["RSS-A"].top_score == 0.5  # the map keeps it
    assert lru2.knowledge.rss["RSS-A"]["top_score"] == 0.5  # and so does LRU2


def test_identify_searches_only_within_its_radius_and_pick_the_whole_region(
    world: World,
) -> None:
    """Seed 1: RSS-A's stones lie 4.4 and 4.8 m from its centre (29, 23)."""
    lru1 = world.add_robot("lru1", "lru_science")
    lru2 = world.add_robot("lru2", "lru_manipulator")
    lru1.x, lru1.y, lru2.x, lru2.y = 29.0, 23.0, 29.5, 23.0
    fleet = exchanging_fleet(world)
    s1, s2 = RobotSkills(fleet, lru1), RobotSkills(fleet, lru2)
    centre = Position(x=29.0, y=23.0)
    gave_up = FakeCtx(replies=["give up"])
    with pytest.raises(SkillFailed, match=r"no stone of RSS-A within 3 m of \(29.0, 23.0\)"):
        call(s1, "identify_stone", gave_up, target=centre, search_radius=3.0)
    assert gave_up.asked[0][1:3] == (["wider", "give up"], "wider")
    assert all(s.state == "hidden" for s in world.stones.values())
    lru1.activity = lru2.activity = "identify_stone"
    call(s1, "identify_stone", target=centre, search_radius=5.0, partner="lru2")
    call(s2, "identify_stone", target=centre, search_radius=5.0, partner="lru1")
    lru1.activity = lru2.activity = None
    stone = world.stones["RSS-A-s1"]
    assert stone.state == "identified" and stone.score == 0.5
    # aimed at the far side of the region, 8.8 m from the stone: it is still found
    result = call(s2, "pick_stone", target=Position(x=29.0, y=18.5))
    assert result.info == "picked RSS-A-s1 of RSS-A (score 0.5); carrying 1/2"


def test_identify_finding_nothing_asks_and_searches_wider_by_default(world: World) -> None:
    """Seed 1: RSS-A's stones lie 4.4 and 4.8 m from (29, 23). Within 3 m there is
    none: the operators are asked; no answer (the default) searches 6 m, which
    costs the ring's share of the search time and its battery, and finds one."""
    lru2 = world.add_robot("lru2", "lru_manipulator")
    lru2.x, lru2.y = 29.0, 23.0
    skills = RobotSkills(fake_fleet(world), lru2)
    ctx = FakeCtx()
    t0, b0 = lru2.sim_seconds, lru2.battery
    found = call(skills, "identify_stone", ctx, target=Position(x=29.0, y=23.0), search_radius=3.0)
    ((text, choices, default, timeout),) = ctx.asked
    assert "no stone of RSS-A within 3 m of (29.0, 23.0). Search wider (6 m)?" in text
    assert (choices, default, timeout) == (["wider", "give up"], "wider", 180.0)
    assert found.info.startswith("identified RSS-A-s")
    wider_s = 36.0 * 3  # the 6 m ring: three times the area of the first 3 m
    assert lru2.sim_seconds - t0 == pytest.approx(wider_s + 120.0)
    assert b0 - lru2.battery == pytest.approx(lru2.work_energy(wider_s + 120.0))
    assert any("searching wider (6 m, by default)" in info for _, info, _ in ctx.progress_calls)


def test_identify_searches_wider_when_the_operator_answers_so(world: World) -> None:
    """The operator's "wider" (before the timeout): the same wider search, saying
    it was answered; the stone is found as by default."""
    lru2 = world.add_robot("lru2", "lru_manipulator")
    lru2.x, lru2.y = 29.0, 23.0
    skills = RobotSkills(fake_fleet(world), lru2)
    ctx = FakeCtx(replies=["wider"])
    t0 = lru2.sim_seconds
    found = call(skills, "identify_stone", ctx, target=Position(x=29.0, y=23.0), search_radius=3.0)
    assert len(ctx.asked) == 1 and ctx.replies == []  # asked once, the answer taken
    assert found.info.startswith("identified RSS-A-s")
    assert lru2.sim_seconds - t0 == pytest.approx(36.0 * 3 + 120.0)
    infos = [info for _, info, _ in ctx.progress_calls]
    assert any("searching wider (6 m, answered)" in info for info in infos)
    assert not any("by default" in info for info in infos)


def test_identify_finding_nothing_gives_up_or_fails_wider_too(world: World) -> None:
    lru2 = world.add_robot("lru2", "lru_manipulator")
    lru2.x, lru2.y = -10.0, -10.0
    skills = RobotSkills(fake_fleet(world), lru2)
    far = Position(x=-10.0, y=-10.0)
    with pytest.raises(
        SkillFailed, match=r"nothing to identify here; the operator \(ann@console\) gave up"
    ):
        call(skills, "identify_stone", FakeCtx(replies=["give up"]), target=far)
    t0 = lru2.sim_seconds
    with pytest.raises(SkillFailed, match=r"within 8 m of \(-10.0, -10.0\), nor within 16 m"):
        call(skills, "identify_stone", FakeCtx(), target=far)
    assert lru2.sim_seconds - t0 == pytest.approx(36.0 * 4)  # the search, then the wider one


async def _together(skills: RobotSkills, robot: Any, **params: Any) -> str:
    """One partner's identify_stone, working on it as the fleet marks it (a barrier);
    the parameters not given with the library's defaults, as in `call`."""
    spec = LIBRARY.skills["identify_stone"]
    params = {**typed_params(spec.signature().defaults, spec.kinds()), **params}
    robot.activity = "identify_stone"
    try:
        return (await skills.identify_stone(FakeCtx(), **params)).info
    finally:
        robot.activity = None


@pytest.mark.parametrize("late", ["lru1", "lru2"])
def test_barrier_partners_name_the_same_stone_when_one_comes_too_late(
    world: World, monkeypatch: pytest.MonkeyPatch, late: str
) -> None:
    """Issue 35: LRU2 gave up waiting for LRU1 and identified a stone alone; LRU1, there
    later, identified another one alone: the two rows named two stones (RSS-E-s2 and
    RSS-E-s1) and the region had none left. The partners name one stone."""
    monkeypatch.setattr(science, "PARTNER_WAIT", 30.0)  # a short wait: LRU1 comes too late
    lru1 = world.add_robot("lru1", "lru_science")
    lru2 = world.add_robot("lru2", "lru_manipulator")
    centre = Position(x=29.0, y=23.0)
    lru1.x, lru1.y, lru2.x, lru2.y = 29.0, 23.0, 29.5, 23.0
    world.robots[late].x = -60.0  # about 180 s away, inside the lander's coverage
    fleet = exchanging_fleet(world)
    s1, s2 = RobotSkills(fleet, lru1), RobotSkills(fleet, lru2)

    async def both() -> list[str]:
        return await asyncio.gather(
            _together(s1, lru1, target=centre, search_radius=6.0, partner="lru2"),
            _together(s2, lru2, target=centre, search_radius=6.0, partner="lru1"),
        )

    one, two = run(both())
    named = {re.search(r"identified (\S+) at", text).group(1) for text in (one, two)}
    assert len(named) == 1, (one, two)
    (sid,) = named
    assert [k.id for k in world.stones.values() if k.state == "identified"] == [sid]
    assert world.stones[sid].score == 0.1  # nobody waited long enough: alone
    early = "lru2" if late == "lru1" else "lru1"
    assert f"{early} had identified it alone" in (one if late == "lru1" else two)


def test_a_robot_trusts_its_own_newer_news_of_a_stone_over_a_partners_stale_one(
    world: World,
) -> None:
    """LRU2 delivered a stone while LRU1 could not hear of it; later LRU1, asked, must not
    send LRU2 back for it (it said 'identified' and LRU2 failed picks on 'delivered')."""
    lru1 = world.add_robot("lru1", "lru_science")
    lru2 = world.add_robot("lru2", "lru_manipulator")
    lru1.x, lru1.y, lru2.x, lru2.y = 29.0, 23.0, 29.5, 23.0
    fleet = exchanging_fleet(world)
    s1, s2 = RobotSkills(fleet, lru1), RobotSkills(fleet, lru2)
    centre = Position(x=29.0, y=23.0)
    lru1.activity = lru2.activity = "identify_stone"
    call(s1, "identify_stone", target=centre, search_radius=6.0, partner="lru2")
    call(s2, "identify_stone", target=centre, search_radius=6.0, partner="lru1")
    lru1.activity = lru2.activity = None
    stale = dict(lru1.knowledge.stones["RSS-A-s1"])
    call(s2, "pick_stone", target=centre)
    lru2.x, lru2.y = 2.0, 0.0
    drop = call(s2, "drop_stone")
    assert drop.info == "delivered RSS-A-s1 of RSS-A +0.5: +0.5; score 0.5"
    lru1.knowledge.stones["RSS-A-s1"] = stale  # it heard nothing of the pick nor the drop
    lru2.x, lru2.y = 29.5, 23.0
    with pytest.raises(SkillFailed) as exc:
        call(s2, "pick_stone", target=centre)
    assert "knows no identified stone" in exc.value.reason, exc.value.reason
    assert lru2.knowledge.stones["RSS-A-s1"]["state"] == "delivered"  # its own news stays
    # told by the one that knows better, LRU1 learns; told stale news, nobody unlearns
    WorldExchange(world, lru1).tell_stone(lru2.knowledge.stones["RSS-A-s1"], "lru2")
    WorldExchange(world, lru2).tell_stone(stale, "lru1")
    assert lru1.knowledge.stones["RSS-A-s1"]["state"] == "delivered"
    assert lru2.knowledge.stones["RSS-A-s1"]["state"] == "delivered"


# ---------------------------------------------------------------- map feed codec


def _meta(h: int, w: int, tile: int = 16) -> mf.MapMeta:
    return mf.MapMeta(world="t", seed=1, x0=0.0, y0=0.0, cell=1.0, width=w, height=h, tile=tile)


def test_tiles_round_trip_and_only_changed_tiles_are_sent() -> None:
    rng = np.random.default_rng(3)
    h, w = 40, 50  # not multiples of 16: edge tiles are smaller
    terrain = rng.integers(0, 4, (h, w)).astype(np.uint8)
    coverage = np.zeros((h, w), dtype=np.uint8)
    enc = mf.TileEncoder(_meta(h, w))
    first = enc.delta({"terrain": terrain, "coverage": coverage})
    assert len(first) == 2 * 3 * 4  # every tile of both layers
    assert enc.delta({"terrain": terrain, "coverage": coverage}) == []  # nothing changed
    mirror = mf.MapMirror()
    mirror.apply_snapshot(
        mf.MapSnapshot(
            meta=enc.meta,
            seq=0,
            sim_time=0.0,
            tiles=enc.full(),
            objects=mf.MapObjects(lander=mf.LanderItem(x=0, y=0, pad_radius=5, comm_radius=60)),
        )
    )
    assert np.array_equal(mirror.layers["terrain"], terrain)
    t2 = terrain.copy()
    t2[0, 0] = (t2[0, 0] + 1) % 4  # tile (0, 0)
    t2[39, 49] = (t2[39, 49] + 1) % 4  # the corner tile (3, 2), 8x2 cells
    c2 = coverage.copy()
    c2[20, 20] = 200  # tile (1, 1)
    tiles = enc.delta({"terrain": t2, "coverage": c2})
    assert sorted((t.layer, t.tx, t.ty) for t in tiles) == [
        ("coverage", 1, 1),
        ("terrain", 0, 0),
        ("terrain", 3, 2),
    ]
    delta = mf.MapDelta(seq=1, sim_time=1.0, tiles=tiles)
    wire = mf.MapDelta.model_validate_json(mf.dump(delta))
    assert mirror.apply_delta(wire)
    assert np.array_equal(mirror.layers["terrain"], t2) and np.array_equal(
        mirror.layers["coverage"], c2
    )
    assert mirror.apply_delta(wire)  # a duplicate is ignored
    assert not mirror.apply_delta(mf.MapDelta(seq=3, sim_time=2.0))  # a gap: re-query the snapshot
    # a changed tile compresses well: the delta is far smaller than the grid
    assert len(mf.dump(delta)) < h * w


def test_mirror_keeps_deltas_that_arrive_before_the_snapshot() -> None:
    grid = np.zeros((16, 16), dtype=np.uint8)
    enc = mf.TileEncoder(_meta(16, 16))
    enc.delta({"terrain": grid, "coverage": grid})
    lander = mf.LanderItem(x=0, y=0, pad_radius=5, comm_radius=60)
    snap = mf.MapSnapshot(
        meta=enc.meta, seq=4, sim_time=0.0, tiles=enc.full(), objects=mf.MapObjects(lander=lander)
    )
    g2 = grid.copy()
    g2[3, 3] = 2
    d5 = mf.MapDelta(
        seq=5,
        sim_time=1.0,
        tiles=enc.delta({"terrain": g2, "coverage": grid}),
        objects=mf.MapObjects(lander=lander, rss=[mf.RssItem(rss="RSS-A", x=1, y=2, radius=3)]),
    )
    mirror = mf.MapMirror()
    assert mirror.apply_delta(d5) and not mirror.ready
    mirror.apply_snapshot(snap)
    assert mirror.seq == 5 and mirror.layers["terrain"][3, 3] == 2
    assert mirror.objects is not None and mirror.objects.rss[0].rss == "RSS-A"
    assert mirror.cell_of(3.5, 3.5) == (3, 3) and mirror.cell_of(-1, 0) is None
    with pytest.raises(ValueError):
        mf.decode_tile(mf.encode_tile(np.zeros((4, 4), dtype=np.uint8)), (5, 5))


def test_mapfeed_is_self_contained() -> None:
    """The wire models stay free of transport and sim: pydantic + numpy + stdlib only."""
    import ast

    tree = ast.parse(Path(mf.__file__).read_text())
    mods = {
        a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names
    }
    mods |= {
        n.module.split(".")[0]
        for n in ast.walk(tree)
        if isinstance(n, ast.ImportFrom) and n.module and n.level == 0
    }
    assert mods <= {"__future__", "base64", "json", "zlib", "typing", "numpy", "pydantic"}, mods
