"""Scripted operators of the ROSMC pilot study (section V-B), for the calibrated world.

Each strategy drives the robots only through what an operator has: the mission
client (add, barrier, sync, run; skill statuses and their result texts; robot
telemetry while in range), the map feed (explored terrain, coverage, regions
and top scores reported, stones, boxes) and the sim's ground status (the score
and the sim clock). Never the world's truth: `run_strategy` reads the truth
only after the strategy is over, to evaluate it.

Operator knowledge: from the pilot study's instruction document, that the
mission lasts about 26.8 minutes; every figure it plans with (how far LRU1's
camera sees, ...) from the skill library, as a newcomer reads them (never the
world file).

    result = await run_strategy(stack, "ideal", seed=1)   # tests/sim/test_pilot_study.py
    python bench/pilot_study.py                            # every strategy, 5 seeds
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any

from backend import transport
from backend.client.client import MissionClient, OperationRefused
from backend.client.mapfollow import MapFeed
from backend.client.simstatus import SimStatusFeed
from backend.core.ops import (
    AddBarrier,
    AddRobot,
    AddSkill,
    Control,
    DeleteSkills,
    Reassign,
    RetireRobot,
    Sync,
    Unsync,
)
from backend.protocol import mapfeed as mf

PILOT_MINUTES = 26.8  # the participants' average mission time
DEADLINE = PILOT_MINUTES * 60.0  # sim seconds
BEST = 1.8  # the paper's best participants scored 1.8 or more
LANDER_DROP = {"x": 2.0, "y": 0.0}
TERMINAL = ("success", "failure")
WAKE_S = 0.1  # wall seconds between looks at the clock while nothing happens
IN_FLIGHT_S = 10.0  # sim seconds the robots' news may take to reach the ground's view

XY = tuple[float, float]


@dataclass
class Region:
    name: str
    x: float
    y: float
    radius: float
    top: float | None

    def dist(self, x: float, y: float) -> float:
        return math.hypot(self.x - x, self.y - y)


@dataclass
class Result:
    strategy: str
    seed: int
    score: float  # delivered within the deadline, as the ground saw it
    reached_best_at: float | None  # sim seconds when the score reached BEST
    deliveries: list[tuple[str, float, float]]  # (stone, score, sim time)
    failures: list[tuple[str, str, str]]  # (robot, skill, reason)
    refusals: list[str]  # operations the server refused (e.g. out of range)
    notes: list[str] = field(default_factory=list)
    seen: dict[str, float] = field(default_factory=dict)  # region -> first on the map (s)
    skills: list[str] = field(default_factory=list)  # "robot skill: status, result" in order
    truth: mf.SimTruth | None = None  # evaluation only, read after the run
    started_at: float = 0.0  # sim seconds when the operator began (robots registered)
    branches: list[str] = field(default_factory=list)  # "robot skill: on failure: skip" taken
    questions: list[str] = field(default_factory=list)  # "robot skill: text -> defaulted wider"

    def took(self) -> float | None:
        """Sim seconds from the operator's start to BEST (None: never)."""
        return None if self.reached_best_at is None else self.reached_best_at - self.started_at

    def within(self, seconds: float) -> float:
        """The score delivered within `seconds` of the operator's start."""
        got = sum(v for _s, v, t in self.deliveries if t - self.started_at <= seconds)
        return round(got, 3)


class Deadline(Exception):
    """The pilot study's time is up."""


class Operator:
    """What the operator sees and does, with waiting on the sim clock."""

    def __init__(self, client: MissionClient, deadline: float = DEADLINE):
        self.client = client
        self.deadline = deadline
        self.status: mf.SimStatus | None = None  # the ground view, live
        self._status_wall = 0.0
        self.changed = asyncio.Event()
        self.feed: MapFeed | None = None
        self.refusals: list[str] = []
        self.notes: list[str] = []
        self.seen: dict[str, float] = {}  # region -> sim time it first showed on the map
        self.shelved: str | None = None  # the lander's skill that shelves the Wi-Fi box
        self._sub: Any = None
        self._loop = asyncio.get_running_loop()

    async def start(self) -> None:
        assert self.client.session is not None
        # full statuses and patches, followed like the map (backend.client.simstatus)
        self._sub = SimStatusFeed(self.client.session, self._set_status, timeout=10.0)
        self.client.add_listener(lambda _event: self.changed.set())
        self.feed = MapFeed(self.client.session, self._on_map)
        await self.feed.start()
        await self._sub.start()

    def close(self) -> None:
        if self.feed is not None:
            self.feed.close()
        if self._sub is not None:
            self._sub.close()

    def _set_status(self, st: mf.SimStatus) -> None:
        if self.status is None or st.sim_time >= self.status.sim_time:
            self.status, self._status_wall = st, self._loop.time()
        self.changed.set()

    # ------------------------------------------------------------ what the operator sees

    def clock(self) -> float:
        """Sim seconds: the last status's clock, moved on at the sim's speed."""
        assert self.status is not None
        return self.status.sim_time + (self._loop.time() - self._status_wall) * self.status.speed

    @property
    def map(self) -> mf.MapMirror:
        assert self.feed is not None
        return self.feed.mirror

    def regions(self) -> dict[str, Region]:
        objs = self.map.objects
        if objs is None:
            return {}
        return {r.rss: Region(r.rss, r.x, r.y, r.radius, r.top_score) for r in objs.rss}

    def _on_map(self, _update: Any) -> None:
        for name in self.regions():
            self.seen.setdefault(name, round(self.clock()))
        self.changed.set()

    def score(self) -> float:
        objs = self.map.objects
        return objs.score if objs is not None else 0.0

    def lander(self) -> mf.LanderItem:
        assert self.map.objects is not None
        return self.map.objects.lander

    def coverage(self, x: float, y: float) -> float:
        cell = self.map.cell_of(x, y)
        return 0.0 if cell is None else float(self.map.layers["coverage"][cell]) / 255.0

    def passable(self, x: float, y: float) -> bool:
        """Explored and not impassable (unexplored ground is a gamble)."""
        cell = self.map.cell_of(x, y)
        return cell is not None and self.map.layers["terrain"][cell] in (mf.T_FREE, mf.T_SLOW)

    def free_near(self, x: float, y: float, within: float = 8.0) -> XY:
        """The nearest explored, passable point to (x, y) (itself if it is one)."""
        best, best_d = (x, y), math.inf
        step = self.map.meta.cell if self.map.meta else 2.0
        n = int(within / step)
        for i in range(-n, n + 1):
            for j in range(-n, n + 1):
                px, py = x + i * step, y + j * step
                d = math.hypot(px - x, py - y)
                if d < best_d and d <= within and self.passable(px, py):
                    best, best_d = (px, py), d
        return best

    def site(self) -> list[dict[str, float]]:
        meta = self.map.meta
        assert meta is not None
        x1, y1 = meta.x0 + meta.width * meta.cell, meta.y0 + meta.height * meta.cell
        return _rect(meta.x0, meta.y0, x1, y1)

    def pose(self, robot: str) -> XY:
        t = self.client.telemetry.get(robot)
        return (t.pose.x, t.pose.y) if t is not None else (0.0, 0.0)

    def battery(self, robot: str) -> float:
        t = self.client.telemetry.get(robot)
        return t.battery if t is not None else 1.0

    def skill(self, sid: str) -> Any:
        assert self.client.mission is not None
        found = self.client.mission.find(sid)
        assert found is not None, sid
        return found[2]

    def figure(self, robot: str, name: str) -> float:
        """A figure the library states for the robot's type (its `properties`)."""
        m, lib = self.client.mission, self.client.library
        assert m is not None and lib is not None
        return float(lib.robot_types[m.robots[robot].type].properties[name])

    def status_of(self, sid: str) -> str:
        return str(self.skill(sid).status.value)

    # ------------------------------------------------------------ waiting

    async def until(self, pred: Callable[[], bool], deadline: float | None = None) -> bool:
        """Wait until `pred()`; False when the sim clock passes `deadline` first."""
        end = self.deadline if deadline is None else min(deadline, self.deadline)
        while not pred():
            if self.clock() >= end:
                return False
            self.changed.clear()
            try:
                await asyncio.wait_for(self.changed.wait(), WAKE_S)
            except TimeoutError:
                pass
        return True

    async def done(self, *ids: str) -> list[str]:
        """Wait for the skills to end (success/failure); raises Deadline when time is up."""
        if not await self.until(lambda: all(self.status_of(i) in TERMINAL for i in ids)):
            raise Deadline
        return [self.status_of(i) for i in ids]

    async def ok(self, *ids: str) -> bool:
        return all(s == "success" for s in await self.done(*ids))

    # ------------------------------------------------------------ acting

    async def clear_plan(self) -> None:
        """Delete the opening mission's plan: this operator writes its own."""
        m = self.client.mission
        assert m is not None
        ids = [s.id for task in m.tasks.values() for s in task]
        if ids:
            await self.client.submit(DeleteSkills(ids=ids))

    async def plan(self, robot: str, *steps: tuple[str, dict[str, Any]]) -> list[str]:
        """Add skills at the end of the robot's list; their ids (not sent yet)."""
        ids = []
        for skill_name, params in steps:
            reply = await self.client.submit(AddSkill(robot=robot, skill=skill_name, params=params))
            ids.append(reply.value["id"])
        return ids

    async def send(self, robot: str, ids: list[str]) -> bool:
        """Synchronize the robot's list through the last id and run it; False if refused
        (e.g. the robot is out of communication range)."""
        try:
            await self.client.submit(Sync(robot=robot, through=ids[-1]))
        except OperationRefused as e:
            self.refusals.append(f"sync {robot}: {e}")
            return False
        try:
            await self.client.submit(Control(op="run", robot=robot))
        except OperationRefused as e:  # already running: the new skills start in turn
            if "out of communication range" in str(e):
                self.refusals.append(f"run {robot}: {e}")
                return False
        return True

    async def do(self, robot: str, *steps: tuple[str, dict[str, Any]]) -> list[str]:
        ids = await self.plan(robot, *steps)
        await self.send(robot, ids)
        return ids

    async def together(self, region: Region, first: str = "lru1", second: str = "lru2") -> bool:
        """LRU1 and LRU2 identify a stone in `region` together (a barrier), then LRU2
        picks it; whether it carries it now."""
        where = _pose((region.x, region.y))
        radius = min(10.0, region.radius + 1.5)
        (a,) = await self.plan(
            first,
            ("identify_stone", {"target": where, "search_radius": radius, "partner": second}),
        )
        (b,) = await self.plan(
            second,
            ("identify_stone", {"target": where, "search_radius": radius, "partner": first}),
        )
        await self.client.submit(AddBarrier(ids=[a, b]))
        await self.send(first, [a])
        await self.send(second, [b])
        if not await self.ok(a, b):
            self.note(f"{region.name}: {self.skill(b).status_info or self.skill(a).status_info}")
            return False
        return await self.ok(*await self.do(second, ("pick_stone", {"target": where})))

    def note(self, text: str) -> None:
        self.notes.append(f"[{self.clock():5.0f} s] {text}")


def _rect(x0: float, y0: float, x1: float, y1: float) -> list[dict[str, float]]:
    return [_pose((x0, y0)), _pose((x1, y0)), _pose((x1, y1)), _pose((x0, y1))]


def _pose(p: XY) -> dict[str, float]:
    """A pose or position parameter (the server fills in the rest)."""
    return {"x": round(p[0], 1), "y": round(p[1], 1)}


# ---------------------------------------------------------------- shared steps


async def explore_near(op: Operator, robot: str, half: str, seconds: float) -> str:
    """A rover maps one half (east or west, or all) of the ground inside the lander's
    coverage."""
    r = op.lander().comm_radius * 0.7
    lx, ly = op.lander().x, op.lander().y
    x0, x1 = {"east": (lx, lx + r), "west": (lx - r, lx), "all": (lx - r, lx + r)}[half]
    area = _rect(x0, ly - r, x1, ly + r)
    (sid,) = await op.do(robot, ("explore", {"area": area, "max_duration": seconds}))
    return sid


async def deliver(op: Operator, robot: str = "lru2") -> bool:
    ids = await op.do(
        robot, ("drive_to", {"goal": _pose((2.0, 0.0)), "speed": 1.0}), ("drop_stone", {})
    )
    return await op.ok(*ids)


async def top_up(
    op: Operator, robots: tuple[str, ...] = ("lru1", "lru2"), below: float = 0.4
) -> None:
    """Recharge the robots whose battery gauge is below `below` (at the lander)."""
    ids = []
    for robot in robots:
        if op.battery(robot) < below:
            op.note(f"{robot} recharges ({op.battery(robot):.0%})")
            ids += await op.do(robot, ("recharge", {"target_level": 0.95}))
    if ids:
        await op.done(*ids)


async def collect(op: Operator, regions: list[Region], per_trip: int = 2) -> None:
    """Identify together and pick, region after region (each until it gives no more),
    delivering every `per_trip` stones. What the naive and the farming operator do."""
    carried = 0
    for region in regions:
        while await op.together(region):
            carried += 1
            if carried >= per_trip:
                await deliver(op)
                carried = 0
                await top_up(op)
    if carried:
        await deliver(op)


def nearest_first(op: Operator, regions: list[Region]) -> list[Region]:
    lx, ly = op.lander().x, op.lander().y
    return sorted(regions, key=lambda g: g.dist(lx, ly))


# ---------------------------------------------------------------- strategies


async def naive(op: Operator) -> None:
    """What a newcomer does: the rovers explore around the lander (no drone, no science
    camera, no Wi-Fi box), then LRU1 and LRU2 take stones together from the regions
    they found, nearest first, two per trip."""
    await op.do("lander", ("load_box", {"box": "wifi_box_1", "slot": 2}))
    east = await explore_near(op, "lru1", "east", 240.0)
    west = await explore_near(op, "lru2", "west", 240.0)
    await op.done(east, west)
    await collect(op, nearest_first(op, list(op.regions().values())))


async def farming(op: Operator) -> None:
    """Farm the nearest region: the orbital hint (POI-A) is explored, the region found
    there is stripped of its stones, two per trip."""
    m = op.client.mission
    assert m is not None
    poi = m.markers["POI-A"].pose
    await op.do("lru1", ("drive_to", {"goal": _pose((poi.x, poi.y))}))
    area = _rect(poi.x - 15, poi.y - 15, poi.x + 15, poi.y + 15)
    (sid,) = await op.do("lru1", ("explore", {"area": area, "max_duration": 150}))
    await op.done(sid)
    await collect(op, nearest_first(op, list(op.regions().values()))[:1])


def clusters(op: Operator, regions: list[Region], link: float = 60.0) -> list[list[Region]]:
    """Regions beyond the lander's coverage, grouped (single link within `link` m)."""
    far = [g for g in regions if op.coverage(g.x, g.y) == 0.0]
    groups: list[list[Region]] = []
    for g in far:
        near = [c for c in groups if any(g.dist(o.x, o.y) <= link for o in c)]
        merged = [g] + [o for c in near for o in c]
        groups = [c for c in groups if c not in near] + [merged]
    return groups


def best_cluster(op: Operator) -> list[Region] | None:
    """The group with the most regions out there (one trip, one Wi-Fi box serve
    them all), nearest the lander among equals; None until one has two regions."""
    lx, ly = op.lander().x, op.lander().y
    groups = [c for c in clusters(op, list(op.regions().values())) if len(c) >= 2]
    if not groups:
        return None
    return max(groups, key=lambda c: (len(c), -min(g.dist(lx, ly) for g in c)))


def relay_spot(op: Operator, target: XY, margin: float = 0.12) -> XY:
    """Where a Wi-Fi box extends coverage towards `target`: on the way from the lander,
    the last explored, passable point the coverage still reaches (quality > margin)."""
    lx, ly = op.lander().x, op.lander().y
    d = math.hypot(target[0] - lx, target[1] - ly)
    ux, uy = (target[0] - lx) / d, (target[1] - ly) / d
    spot = (lx, ly)
    for k in range(int(d)):
        p = (lx + ux * k, ly + uy * k)
        if op.coverage(*p) > margin and op.passable(*p):
            spot = p
    return spot


def image_spot(op: Operator, region: Region, start: XY) -> XY:
    """Where LRU1 stops to image a region: a little short of it, on its way."""
    d = region.dist(*start)
    back = min(d, op.figure("lru1", "camera_range_m") * 0.5)
    k = 0.0 if d == 0 else (d - back) / d
    return op.free_near(start[0] + (region.x - start[0]) * k, start[1] + (region.y - start[1]) * k)


async def survey_from_the_air(op: Operator, altitude: float = 10.0) -> list[str]:
    """Ardea maps the whole site in one flight (at 10 m its camera sees 40 m: 427 s), lands.
    The survey is capped at 480 s (the library predicts 427 s at 240 m²/s)."""
    return await op.do(
        "ardea",
        ("takeoff", {"altitude": altitude}),
        ("explore", {"area": op.site(), "max_duration": 480}),
        ("land", {"where": "lander_pad"}),
    )


async def ideal(op: Operator, *, mind_batteries: bool = True, use_wifi: bool = True) -> None:
    """The paper's best: all three robots explore, LRU1's camera reveals the top scores
    of the regions found out there, LRU2 extends the coverage to them with a Wi-Fi
    box, and LRU1 and LRU2 take the two most valuable stones together.

    `mind_batteries=False`: the same plan by an operator who never looks at the
    batteries (the rovers explore as long as there is something to explore, nobody
    recharges). `use_wifi=False`: one who ignores the coverage (no Wi-Fi box: the
    whole plan goes out with the rovers, beyond reach)."""
    lru1, lru2 = await explore_with_all_three(op, mind_batteries)
    if not await op.until(lambda: best_cluster(op) is not None):
        return
    cluster = best_cluster(op)
    assert cluster is not None
    op.note(
        "out there: "
        + ", ".join(g.name for g in cluster)
        + "; batteries "
        + ", ".join(f"{r} {op.battery(r):.0%}" for r in ("lru1", "lru2"))
    )
    await op.done(*lru2)
    if use_wifi:
        await bring_coverage(op, cluster)
    await op.done(*lru1)
    images = await image_all(op, cluster)
    if use_wifi:  # the top scores LRU1 revealed decide (once they reached the ground)
        await op.done(*images)
        await op.until(lambda: _all_known(op, cluster), op.clock() + 60.0)
        targets = _two_best(op, cluster)
    else:  # out of reach the scores cannot be seen, nor the plan changed: all of it now
        lx, ly = op.lander().x, op.lander().y
        targets = sorted(cluster, key=lambda g: g.dist(lx, ly))[:2]
    op.note("taking " + ", ".join(f"{g.name} (top {g.top})" for g in targets))
    await take_together(op, targets)


async def explore_with_all_three(op: Operator, mind_batteries: bool) -> tuple[list[str], list[str]]:
    """Ardea surveys the site; the rovers map the ground near the lander meanwhile (and
    recharge, unless batteries are ignored); LRU2 comes back for the Wi-Fi box."""
    (op.shelved,) = await op.do("lander", ("load_box", {"box": "wifi_box_1", "slot": 2}))
    await survey_from_the_air(op)
    if mind_batteries:
        lru1 = [await explore_near(op, "lru1", "east", 200.0)]
        lru2 = [await explore_near(op, "lru2", "west", 100.0)]
    else:  # the rovers explore as long as there is something to explore
        lru1 = [await explore_near(op, "lru1", "all", 400.0)]
        lru2 = [await explore_near(op, "lru2", "all", 400.0)]
    lru2 += await op.do("lru2", ("drive_to", {"goal": _pose((3.0, -2.0)), "speed": 1.0}))
    if mind_batteries:  # full batteries before the long trip
        lru1 += await op.do("lru1", ("recharge", {"target_level": 0.95}))
        lru2 += await op.do("lru2", ("recharge", {"target_level": 0.95}))
    return lru1, lru2


async def bring_coverage(op: Operator, cluster: list[Region]) -> None:
    """LRU2 deploys a Wi-Fi box towards the group, then waits amid the group."""
    cx = sum(g.x for g in cluster) / len(cluster)
    cy = sum(g.y for g in cluster) / len(cluster)
    spot = relay_spot(op, (cx, cy))
    op.note(f"Wi-Fi box at ({spot[0]:.0f}, {spot[1]:.0f})")
    await op.do(
        "lru2",
        ("deploy_wifi_box", {"box": "wifi_box_1", "goal": _pose(spot)}),
        ("drive_to", {"goal": _pose(op.free_near(cx, cy)), "speed": 1.0}),
    )


async def image_all(op: Operator, cluster: list[Region], robot: str = "lru1") -> list[str]:
    """LRU1 (or the robot in its place) images the regions of the group, nearest first."""
    here = op.pose(robot)
    images = []
    for region in sorted(cluster, key=lambda g: g.dist(*here)):
        spot = image_spot(op, region, here)
        images += await op.do(
            robot,
            ("drive_to", {"goal": _pose(spot), "speed": 1.0}),
            ("take_science_image", {"target": _pose((region.x, region.y))}),
        )
        here = spot
    return images


async def take_together(
    op: Operator, targets: list[Region], first: str = "lru1", approach: bool = False
) -> None:
    """One plan for both rovers: at each region a barrier (identify together) and LRU2
    picks; then LRU2 drives home and drops the stones into the sample box. `first`: LRU1
    or the robot in its place; `approach`: both drive to each region at full speed first
    (identify goes there at cruise speed)."""
    pair = ((first, "lru2"), ("lru2", first))
    steps: dict[str, list[tuple[str, dict[str, Any]]]] = {first: [], "lru2": []}
    at: dict[str, list[int]] = {first: [], "lru2": []}  # where each identifies
    for region in targets:
        where, radius = _pose((region.x, region.y)), min(10.0, region.radius + 1.5)
        for robot, partner in pair:
            if approach:
                goal = _pose(op.free_near(region.x, region.y))
                steps[robot].append(("drive_to", {"goal": goal, "speed": 1.0}))
            at[robot].append(len(steps[robot]))
            look = {"target": where, "search_radius": radius, "partner": partner}
            steps[robot].append(("identify_stone", look))
        steps["lru2"].append(("pick_stone", {"target": where}))
    steps["lru2"] += [("drive_to", {"goal": _pose((2.0, 0.0)), "speed": 1.0}), ("drop_stone", {})]
    ids = {robot: await op.plan(robot, *steps[robot]) for robot, _ in pair}
    for i, j in zip(at[first], at["lru2"], strict=True):
        await op.client.submit(AddBarrier(ids=[ids[first][i], ids["lru2"][j]]))
    await op.send(first, ids[first])
    await op.send("lru2", ids["lru2"])
    await op.done(ids["lru2"][-1])


def _all_known(op: Operator, cluster: list[Region]) -> bool:
    regions = op.regions()
    return all(regions[g.name].top is not None for g in cluster if g.name in regions)


def _two_best(op: Operator, cluster: list[Region]) -> list[Region]:
    """The two regions with the highest revealed top score where LRU1 and LRU2 can talk
    (covered); unknown scores count last, then the nearest."""
    regions = op.regions()
    lx, ly = op.lander().x, op.lander().y
    now = [regions.get(g.name, g) for g in cluster]
    covered = [g for g in now if op.coverage(g.x, g.y) > 0] or now
    return sorted(covered, key=lambda g: (-(g.top or 0.0), g.dist(lx, ly)))[:2]


async def ignoring_batteries(op: Operator) -> None:
    await ideal(op, mind_batteries=False)


async def ignoring_coverage(op: Operator) -> None:
    await ideal(op, use_wifi=False)


# ---------------------------------------------------------------- a robot substituted (issue 30)

BROKEN = "lru1"
PARTNER = "lru2"  # LRU1's partner at the barriers
QUIET = ("idle", "idle_synchronized", *TERMINAL)  # nothing under way


async def substituted(op: Operator) -> None:
    """The ideal plan until LRU1 stops responding (`--break lru1@12m`). LRU2 is stopped
    at once (a partner that waits for LRU1 would wait in vain, or identify alone) and
    its queue taken back. A robot of LRU1's type arrives (`--join lru3:lru_science@15m`):
    the operator adds it, retires LRU1 and gives it LRU1's remaining plan (two actions),
    then goes on with it in LRU1's part."""
    plan = asyncio.create_task(ideal(op))
    cluster: list[Region] = []  # the ideal's target, seen before the Wi-Fi box covers it

    def broken() -> bool:
        if not cluster:
            cluster.extend(best_cluster(op) or [])
        return plan.done() or not op.client.robots[BROKEN].online

    await op.until(broken)
    if plan.done():
        return await plan  # LRU1 never broke down (or the time was up: Deadline)
    await _stop(plan)
    op.note(f"{BROKEN} stopped responding: the ideal plan stops here")
    await halt(op, PARTNER)
    new = await take_over(op, BROKEN)
    if new is not None:
        await finish_with(op, new, cluster)


async def _stop(task: asyncio.Task[None]) -> None:
    """Cancel `task` until it ends: Python 3.11's wait_for (in Operator.until) can
    swallow a cancellation that meets its timeout."""
    while not task.done():
        task.cancel()
        await asyncio.wait([task], timeout=0.05)
    if not task.cancelled() and task.exception() is not None:
        raise task.exception()  # type: ignore[misc]


async def halt(op: Operator, robot: str) -> None:
    """Take the robot's queue back (its plan is the operator's again), stopping it if it
    identifies with LRU1: alone it would find a low-score stone. Another skill ends."""
    if any(s.skill == "identify_stone" for s in _all(op, robot) if s.status.value not in QUIET):
        with contextlib.suppress(OperationRefused):  # it ended meanwhile
            await op.client.submit(Control(op="stop", robot=robot))
        op.note(f"{robot} stopped")
    # a stopped skill goes back to the head of its queue: then the queue comes back
    await op.until(lambda: all(s.status.value in QUIET for s in _all(op, robot)))
    if any(s.status.value == "idle_synchronized" for s in _all(op, robot)):
        await op.client.submit(Unsync(robot=robot))
    await op.until(lambda: all(s.status.value in ("idle", *TERMINAL) for s in _all(op, robot)))
    op.note(f"{robot}'s queue taken back")


def _joining(op: Operator) -> list[str]:
    return [r for r, info in op.client.robots.items() if info.joining]


async def take_over(op: Operator, broken: str) -> str | None:
    """Add the robot that asks to join, retire `broken` and give it its plan: its name
    (None: nobody came in time)."""
    if not await op.until(lambda: bool(_joining(op))):
        return None
    new = _joining(op)[0]
    manifest = op.client.robots[new].manifest
    assert manifest is not None
    await op.client.submit(AddRobot(name=new, type=manifest.type))
    await op.until(lambda: op.client.robots[new].online)
    retired = await op.client.submit(RetireRobot(name=broken, reason="stopped responding"))
    plan = retired.value["to_reassign"]
    op.note(f"{new} ({manifest.type}) added; {broken} retired, its plan: {plan}")
    if plan:
        given = await op.client.submit(Reassign(from_robot=broken, to=new))
        op.note(f"given to {new}: {given.value['moved']}, staying: {given.value['refused']}")
    return new


async def finish_with(op: Operator, robot: str, cluster: list[Region]) -> None:
    """LRU1's part, by `robot`, with LRU2: the coverage if it is not there yet, the
    images still to take (none once the two best known top scores reach BEST), then
    the best stones together, as many as LRU2 can still carry."""
    if not cluster:  # LRU1 broke before the survey found the group
        if not await op.until(lambda: best_cluster(op) is not None):
            return
        cluster = best_cluster(op) or []
    # the identifications planned with LRU1 are planned again, with `robot`
    stale = [s.id for s in _task(op, PARTNER)]
    stale += [s.id for s in _task(op, robot) if s.skill == "identify_stone"]
    if stale:
        await op.client.submit(DeleteSkills(ids=stale))
    if not _succeeded(op, PARTNER, "deploy_wifi_box"):
        await bring_coverage(op, cluster)
    await _images(op, robot, cluster)
    free = int(op.figure(PARTNER, "carry_stones")) - _carried(op, PARTNER)
    targets = _two_best(op, cluster)[: max(0, free)]
    op.note(f"{robot} takes " + ", ".join(f"{g.name} (top {g.top})" for g in targets))
    await take_together(op, targets, first=robot, approach=True)


async def _images(op: Operator, robot: str, cluster: list[Region]) -> None:
    """The images given to `robot` (LRU1's), and those of the regions still unknown."""
    given = [s.id for s in _task(op, robot)]
    if given and _enough_known(op, cluster):
        op.note(f"the top scores known reach {BEST}: {robot} drops {given}")
        await op.client.submit(DeleteSkills(ids=given))
    elif given:
        await op.send(robot, given)
        await op.done(*given)
    if not _enough_known(op, cluster):
        unknown = [g for g in cluster if op.regions().get(g.name, g).top is None]
        await op.done(*await image_all(op, unknown, robot))
        await op.until(lambda: _all_known(op, cluster), op.clock() + 60.0)


def _all(op: Operator, robot: str) -> list[Any]:
    m = op.client.mission
    assert m is not None
    return list(m.tasks.get(robot, []))


def _task(op: Operator, robot: str) -> list[Any]:
    """The robot's unsynchronized plan."""
    return [s for s in _all(op, robot) if s.status.value == "idle"]


def _succeeded(op: Operator, robot: str, skill: str) -> bool:
    return any(s.skill == skill and s.status.value == "success" for s in _all(op, robot))


def _carried(op: Operator, robot: str) -> int:
    """Stones the robot picked since it last dropped them (its skills' outcomes)."""
    n = 0
    for s in _all(op, robot):
        if s.status.value == "success":
            n = n + 1 if s.skill == "pick_stone" else (0 if s.skill == "drop_stone" else n)
    return n


def _enough_known(op: Operator, cluster: list[Region]) -> bool:
    """The two best top scores revealed reach BEST: other images cannot matter."""
    regions = op.regions()
    tops = sorted((regions[g.name].top or 0.0 for g in cluster if g.name in regions), reverse=True)
    return sum(tops[:2]) >= BEST - 1e-9


# the simulator's options a strategy needs (bench/pilot_study.py, the tests)
SIM_OPTIONS: dict[str, list[str]] = {
    "substituted": ["--break", f"{BROKEN}@12m", "--join", "lru3:lru_science@15m"],
}
# sim seconds a strategy plays on after the deadline, so that a late delivery's time
# is known (its score counts only what was delivered in time)
OVERTIME: dict[str, float] = {"substituted": 600.0}


Strategy = Callable[[Operator], Awaitable[None]]

STRATEGIES: dict[str, Strategy] = {  # at no delay
    "naive": naive,
    "farming": farming,
    "ideal": ideal,
    "ignoring_batteries": ignoring_batteries,
    "ignoring_coverage": ignoring_coverage,
    "substituted": substituted,
}


# ---------------------------------------------------------------- running one


async def play(
    client: MissionClient,
    strategy: str,
    seed: int,
    *,
    deadline: float = DEADLINE,
    linger: bool = True,
    strategies: dict[str, Strategy] | None = None,
) -> Result:
    """Play `strategy` until it is done or `deadline` (sim seconds, and the
    strategy's OVERTIME) is up; evaluate. `linger`: wait out the deadline first
    (reports in flight), or a moment after overtime; a delayed run ends once
    its strategy saw its last skill end."""
    op = Operator(client, deadline + OVERTIME.get(strategy, 0.0))
    await op.start()
    try:
        started = op.clock()  # under a delay the robots register one delay into the run
        await op.clear_plan()
        try:
            await (strategies or STRATEGIES)[strategy](op)
        except Deadline:
            op.note("time is up")
        if linger:  # the rest of the 26.8 minutes (reports in flight), or a moment after overtime
            await op.until(lambda: False, max(deadline, op.clock() + IN_FLIGHT_S))
        result = await _evaluate(op, strategy, seed, deadline, referee=not linger)
        result.started_at = started
        return result
    finally:
        op.close()


async def _evaluate(
    op: Operator, strategy: str, seed: int, deadline: float, referee: bool = False
) -> Result:
    """The deliveries as the ground saw them; `referee`: as the world has them
    (a run that ends as soon as its last skill ended: the ground view of the
    delivery may still be on its way)."""
    assert op.client.session is not None
    raw = await transport.query(op.client.session, mf.KEY_STATUS, mf.TRUTH_QUERY, timeout=10.0)
    status = mf.SimStatus.model_validate_json(raw)
    seen = status.truth.delivered if referee and status.truth is not None else status.delivered
    deliveries = [(d.stone, d.score, d.sim_time) for d in seen]
    score, reached = _scored(deliveries, deadline)
    return Result(
        strategy=strategy,
        seed=seed,
        score=score,
        reached_best_at=reached,
        deliveries=deliveries,
        refusals=op.refusals,
        notes=op.notes,
        seen=op.seen,
        truth=status.truth,
        **_what_the_skills_did(op),
    )


def _what_the_skills_did(op: Operator) -> dict[str, Any]:
    """Result's failures, skills and branches, from the ground's mission."""
    m = op.client.mission
    assert m is not None
    skills = [(robot, s) for robot, task in m.tasks.items() for s in task]
    return {
        "failures": [(r, s.skill, s.status_info) for r, s in skills if s.status.value == "failure"],
        "skills": [f"{r} {s.skill}: {s.status.value} {s.status_info}".rstrip() for r, s in skills],
        "branches": [
            f"{r} {s.skill}: on {s.branch.trigger}: {s.branch.branch}"
            for r, s in skills
            if s.branch is not None
        ],
        "questions": [
            f"{q.robot} {q.skill}: {q.text} -> {q.state.value} {q.choice or ''}".rstrip()
            for asked in m.questions.values()
            for q in asked
        ],
    }


def _scored(
    deliveries: list[tuple[str, float, float]], deadline: float
) -> tuple[float, float | None]:
    """The score delivered by `deadline` and when it reached BEST (None: never)."""
    score, reached = 0.0, None
    for _stone, s, t in sorted((d for d in deliveries if d[2] <= deadline), key=lambda d: d[2]):
        score += s
        if reached is None and score >= BEST - 1e-9:
            reached = t
    return round(score, 3), reached
