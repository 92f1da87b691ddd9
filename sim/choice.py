"""How a simulated robot chooses a marker's place on board (`RobotAgent.on_choose`,
docs/robots.md "Places chosen on board"): from the regions it knows, and what
the robots the rule names tell it (a survey drone, asked over the site
network: only while both can talk, `World.can_talk`).

The rules (`ChooseRule`): among the regions beyond the lander's coverage (or
all), the group with the most regions (single link within `LINK_M`, the
nearest the lander among equals); in it the two closest together
(`closest_pair`) or the best revealed top scores (`best_score`), nearest the
lander first; `rank` takes one of them; `place` its centre (`region`), the
nearest explored passable point (`approach`), or where a Wi-Fi box on the
lander's coverage covers the picked pair (`relay`). While fewer than two
regions are known beyond the coverage it does not know enough (None: the
agent asks again). The map it reads (explored cells, terrain) is the team's
shared one, the world's: a robot knows what any robot mapped.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from itertools import chain
from typing import Any

from backend.agent import Choice
from backend.core.model import ChooseRule, Pose
from sim.robot import SimRobot
from sim.world import World

LINK_M = 60.0  # regions this close to one of a group belong to it
APPROACH_M = 8.0  # how far from a region's centre an approach point may lie
RELAY_MARGIN = 0.12  # the link quality a Wi-Fi box's spot must still have

Region = dict[str, Any]  # a region as a robot knows it (sim.objects.RssState.sighting)
# the fleet's ask (SimFleet.ask): sender, robot asked, topic, data -> its answer
Ask = Callable[[SimRobot, str, str, dict[str, Any]], Awaitable[dict[str, Any] | None]]


class SimChooser:
    """One simulated robot's choice hook."""

    def __init__(self, ask: Ask, world: World, robot: SimRobot):
        self.ask = ask
        self.world = world
        self.robot = robot

    async def __call__(self, choice: Choice) -> Pose | None:
        for other in choice.rule.ask:
            await self._learn_from(other)
        picked = pick(self.world, list(self.robot.knowledge.rss.values()), choice.rule)
        where = None if picked is None else place(self.world, picked, choice.rule)
        if picked is None or where is None:
            return None
        self.world.log(
            f"{self.robot.name} chose {choice.marker} at ({where[0]:.1f}, {where[1]:.1f}): "
            f"{choice.rule.describe()} ({', '.join(g['rss'] for g in picked)})"
        )
        return Pose(x=round(where[0], 1), y=round(where[1], 1))

    async def _learn_from(self, other: str) -> None:
        """What `other` knows of the regions (nothing while they cannot talk)."""
        answer = await self.ask(self.robot, other, "rss", {}) if other != self.robot.name else None
        for region in (answer or {}).get("regions", []):
            self.robot.knowledge.learn_rss(region)


def pick(world: World, regions: list[Region], rule: ChooseRule) -> list[Region] | None:
    """The picked regions, nearest the lander first; None while not enough is known."""
    lander = world.spec.lander
    if rule.among == "regions_beyond_coverage":
        regions = [g for g in regions if _to_lander(world, g) > lander.comm_radius]
    group = best_group(world, regions)
    if group is None:
        return None
    chosen = closest_pair(group) if rule.pick == "closest_pair" else best_two(world, group)
    return sorted(chosen, key=lambda g: (_to_lander(world, g), g["rss"]))


def best_two(world: World, group: list[Region]) -> list[Region]:
    """The two best revealed top scores (unknown ones last), the nearest among equals."""
    return sorted(group, key=lambda g: (-(g.get("top_score") or 0.0), _to_lander(world, g)))[:2]


def best_group(world: World, regions: list[Region]) -> list[Region] | None:
    """The group with the most regions (one trip serves them), the nearest the
    lander among equals; None until one has two regions."""
    groups = [c for c in _groups(regions) if len(c) >= 2]
    if not groups:
        return None
    return max(groups, key=lambda c: (len(c), -min(_to_lander(world, g) for g in c)))


def _groups(regions: list[Region]) -> list[list[Region]]:
    """The regions grouped: single link within LINK_M."""
    groups: list[list[Region]] = []
    for g in sorted(regions, key=lambda r: str(r["rss"])):
        near = [c for c in groups if _links(g, c)]
        groups = [c for c in groups if c not in near] + [[g, *chain.from_iterable(near)]]
    return groups


def _links(g: Region, group: list[Region]) -> bool:
    return any(_dist(g, o) <= LINK_M for o in group)


def closest_pair(group: list[Region]) -> list[Region]:
    pairs = [(_dist(a, b), a, b) for i, a in enumerate(group) for b in group[i + 1 :]]
    _d, a, b = min(pairs, key=lambda p: (p[0], p[1]["rss"], p[2]["rss"]))
    return [a, b]


def place(world: World, picked: list[Region], rule: ChooseRule) -> tuple[float, float] | None:
    """Where the rule's `place` is for the picked regions (None: no such rank)."""
    if rule.place == "relay":
        cx = sum(g["x"] for g in picked) / len(picked)
        cy = sum(g["y"] for g in picked) / len(picked)
        return relay_spot(world, (cx, cy))
    if rule.rank > len(picked):
        return None
    g = picked[rule.rank - 1]
    if rule.place == "region":
        return float(g["x"]), float(g["y"])
    return approach(world, float(g["x"]), float(g["y"]))


def approach(world: World, x: float, y: float) -> tuple[float, float]:
    """The nearest explored, passable point to (x, y) within APPROACH_M (itself
    if it is one)."""
    best, best_d = (x, y), math.inf
    step = world.geom.cell
    n = int(APPROACH_M / step)
    for i in range(-n, n + 1):
        for j in range(-n, n + 1):
            px, py = x + i * step, y + j * step
            d = math.hypot(px - x, py - y)
            if d < best_d and d <= APPROACH_M and _known_passable(world, px, py):
                best, best_d = (px, py), d
    return best


def relay_spot(world: World, target: tuple[float, float]) -> tuple[float, float]:
    """On the way from the lander to `target`, the last explored, passable point
    the coverage still reaches (quality above RELAY_MARGIN)."""
    lx, ly = world.spec.lander.x, world.spec.lander.y
    d = math.hypot(target[0] - lx, target[1] - ly)
    if d == 0:
        return lx, ly
    ux, uy = (target[0] - lx) / d, (target[1] - ly) / d
    spot = (lx, ly)
    for k in range(int(d)):
        p = (lx + ux * k, ly + uy * k)
        if world.link_quality(*p) > RELAY_MARGIN and _known_passable(world, *p):
            spot = p
    return spot


def _known_passable(world: World, x: float, y: float) -> bool:
    g = world.geom
    return g.inside(x, y) and bool(world.explored[g.cell_of(x, y)]) and world.terrain.passable(x, y)


def _to_lander(world: World, g: Region) -> float:
    return world.dist_to_lander(float(g["x"]), float(g["y"]))


def _dist(a: Region, b: Region) -> float:
    return math.hypot(float(a["x"]) - float(b["x"]), float(a["y"]) - float(b["y"]))
