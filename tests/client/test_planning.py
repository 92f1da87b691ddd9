"""The map feed's mirror as the plan's site map: coverage, terrain, routes round
impassable ground, the lander as home, and a version that follows the map."""

from __future__ import annotations

import math
from datetime import UTC, datetime

import numpy as np

from backend.client.planning import MirrorSite, link_of, robot_now
from backend.core.model import Pose
from backend.protocol.mapfeed import (
    T_FREE,
    T_ROCK,
    T_UNKNOWN,
    CommsWindowSpec,
    LanderItem,
    MapDelta,
    MapMeta,
    MapMirror,
    MapObjects,
    MapSnapshot,
    SimStatus,
    TileEncoder,
)
from backend.protocol.messages import Telemetry

N = 50  # cells of 2 m: the site spans -50..50 m


def mirror(terrain: np.ndarray, coverage: np.ndarray) -> tuple[MapMirror, TileEncoder]:
    meta = MapMeta(world="t", seed=1, x0=-50, y0=-50, cell=2.0, width=N, height=N, tile=16)
    enc = TileEncoder(meta)
    tiles = enc.delta({"terrain": terrain, "coverage": coverage})
    m = MapMirror()
    objects = MapObjects(lander=LanderItem(x=1.0, y=-1.0, pad_radius=5, comm_radius=30))
    m.apply_snapshot(
        MapSnapshot(feed="f", meta=meta, seq=0, sim_time=0, tiles=tiles, objects=objects)
    )
    return m, enc


def cell(x: float, y: float) -> tuple[int, int]:
    return int((y + 50) // 2), int((x + 50) // 2)


def site(wall: bool = False, unknown_east: bool = False):
    terrain = np.full((N, N), T_FREE, dtype=np.uint8)
    if wall:  # a wall at x = 0 from y = -40 to 40
        for y in range(-40, 41):
            terrain[cell(0, y)] = T_ROCK
    if unknown_east:
        terrain[:, cell(30, 0)[1] :] = T_UNKNOWN
    coverage = np.zeros((N, N), dtype=np.uint8)
    for i in range(N):
        for j in range(N):
            if math.hypot(-49 + 2 * j, -49 + 2 * i) <= 20:
                coverage[i, j] = 200
    m, enc = mirror(terrain, coverage)
    return MirrorSite(m), m, enc, terrain, coverage


def test_coverage_terrain_and_home_from_the_grids():
    s, *_ = site(wall=True, unknown_east=True)
    assert s.covered(0, 0) is True and s.covered(40, 0) is False
    assert s.covered(500, 0) is None  # outside the map
    assert s.passable(0, 10) is False and s.passable(-10, 10) is True
    assert s.passable(40, 0) is None and s.explored(40, 0) is False
    assert s.explored(-10, 0) is True
    assert s.home() == (1.0, -1.0)


def test_a_route_goes_round_a_wall_and_is_straight_when_clear():
    s, *_ = site(wall=True)
    assert s.route_length((-20, -45), (20, -45)) == 40.0  # below the wall: straight
    around = s.route_length((-10, 0), (10, 0))
    assert 80 < around < 120  # up and over the wall's end at y = 40, and back
    assert s.route_length((-10, 0), (0, 0)) == math.inf  # the goal is in the rocks


def test_no_route_when_walled_in():
    terrain = np.full((N, N), T_FREE, dtype=np.uint8)
    i, j = cell(20, 20)
    terrain[i - 2 : i + 3, j - 2 : j + 3] = T_ROCK
    terrain[i, j] = T_FREE  # a free cell ringed by rocks
    m, _ = mirror(terrain, np.zeros((N, N), dtype=np.uint8))
    assert MirrorSite(m).route_length((-20, -20), (20, 20)) == math.inf


def test_the_version_changes_with_the_map_not_with_every_delta():
    s, m, enc, terrain, coverage = site()
    v0 = s.version
    m.apply_delta(
        MapDelta(
            feed="f", seq=1, sim_time=1, tiles=enc.delta({"terrain": terrain, "coverage": coverage})
        )
    )
    assert s.version == v0  # nothing changed
    coverage[cell(40, 0)] = 100
    m.apply_delta(
        MapDelta(
            feed="f", seq=2, sim_time=2, tiles=enc.delta({"terrain": terrain, "coverage": coverage})
        )
    )
    assert s.version != v0 and s.covered(40, 0) is True


def test_telemetry_and_sim_status_become_plan_inputs():
    at = datetime(2030, 1, 1, tzinfo=UTC)
    t = Telemetry(
        robot="lru1",
        pose=Pose(x=3, y=4),
        battery=0.5,
        skill="lru1-2",
        progress=0.25,
        eta_s=30.0,
        mode="running",
        at=at,
    )
    now = robot_now(t)
    assert (now.at, now.position, now.battery, now.skill, now.eta_s) == (
        at.timestamp(),
        (3.0, 4.0),
        0.5,
        "lru1-2",
        30.0,
    )
    status = SimStatus(world="w", seed=1, speed=4.0, link_delay_s=12.0, sim_time=0, score=0)
    # the sim's delay is sim time; the forecast's clock is the wall's
    assert link_of(status).one_way_s == 3.0 and link_of(None).one_way_s == 0.0
    assert link_of(status).windows == ()  # always in contact


def test_the_sims_comms_windows_become_wall_times_from_now():
    window = CommsWindowSpec(open_s=1200, period_s=7200)  # 20 min every 2 h, sim time
    status = SimStatus(world="w", seed=1, speed=60.0, sim_time=1800, score=0, comms_window=window)
    link = link_of(status, now=1000.0)  # 30 min in: the first window closed 10 min ago
    assert link.windows[:2] == ((970.0, 990.0), (1090.0, 1110.0))  # wall s at 60x
    assert link.reaches(1000.0) == 1090.0  # a command now waits for the next contact
    assert link.reaches(1095.0) == 1095.0  # inside it: at once
