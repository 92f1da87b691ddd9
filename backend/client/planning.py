"""What a client hands the plan's predictions and checks (backend.core.plan):
telemetry as `RobotNow`, the simulator's status as the link model and speed,
and the map feed's mirror as a `SiteMap`.

`MirrorSite` answers from the mirror's numpy grids (rows south to north,
columns west to east): coverage > 0 is covered, terrain 3 impassable, 0
unexplored (and then nobody knows whether it is passable). A rover's route
is the straight line when no impassable cell lies on it, else the shortest
8-connected way round on the grid (A*, unexplored cells counted passable),
cached per terrain. Slow ground (sand) is not counted longer: a known
underestimate of time on sand.
"""

from __future__ import annotations

import heapq
import logging
import math
from collections import OrderedDict
from collections.abc import Mapping
from typing import Any

from pydantic import ValidationError

from backend.core.plan.geometry import Point
from backend.core.plan.inputs import LinkModel, PlanInputs, RobotNow
from backend.protocol.mapfeed import (
    KEY_MAP_SNAPSHOT,
    KEY_STATUS,
    T_ROCK,
    T_UNKNOWN,
    MapMirror,
    MapSnapshot,
    SimStatus,
)
from backend.protocol.messages import Telemetry
from backend.transport import QueryFailed, query

log = logging.getLogger(__name__)

ROUTES_KEPT = 4096
SQRT2 = math.sqrt(2.0)


def robot_now(t: Telemetry) -> RobotNow:
    return RobotNow(
        at=t.at.timestamp(),
        x=t.pose.x,
        y=t.pose.y,
        battery=t.battery,
        skill=t.skill,
        progress=t.progress,
        eta_s=t.eta_s,
        mode=t.mode,
    )


WINDOWS_AHEAD = 48  # contact windows a forecast looks ahead


def link_of(status: SimStatus | None, now: float = 0.0) -> LinkModel:
    """The simulator's link as the forecast's model, in wall seconds (the
    forecast's clock): its one-way delay and, when it has comms windows, the
    next `WINDOWS_AHEAD` of them from `now` (the status's sim time taken as now)."""
    if status is None:
        return LinkModel()
    speed = status.speed if status.speed > 0 else 1.0
    w = status.comms_window
    windows: tuple[tuple[float, float], ...] = ()
    if w is not None:
        phase = (status.sim_time - w.offset_s) % w.period_s
        first = status.sim_time - phase  # the current period's start, sim time
        windows = tuple(
            (
                now + (first + k * w.period_s - status.sim_time) / speed,
                now + (first + k * w.period_s + w.open_s - status.sim_time) / speed,
            )
            for k in range(WINDOWS_AHEAD)
        )
    return LinkModel(one_way_s=status.link_delay_s / speed, windows=windows)


def plan_inputs(
    now: float,
    telemetry: Mapping[str, Telemetry],
    site: MirrorSite | None = None,
    status: SimStatus | None = None,
) -> PlanInputs:
    """Everything a client knows, for backend.core.plan."""
    return PlanInputs(
        now=now,
        robots={r: robot_now(t) for r, t in telemetry.items()},
        site=site if site is not None and site.mirror.ready else None,
        link=link_of(status, now),
        speed=status.speed if status is not None and status.speed > 0 else 1.0,
    )


async def fetch_site(session: Any, timeout: float) -> tuple[MirrorSite | None, SimStatus | None]:
    """The map and the simulator's status, asked once (ctl); None for what
    nobody answers (no simulator: no map, no speed, no link delay)."""
    site: MirrorSite | None = None
    try:
        mirror = MapMirror()
        mirror.apply_snapshot(
            MapSnapshot.model_validate_json(await query(session, KEY_MAP_SNAPSHOT, b"", timeout))
        )
        site = MirrorSite(mirror)
    except (QueryFailed, ValidationError, ValueError) as e:
        log.info("no site map: %s", e)
    return site, await fetch_status(session, timeout)


async def fetch_status(session: Any, timeout: float) -> SimStatus | None:
    """The simulator's status, asked once; None when no simulator answers."""
    try:
        return SimStatus.model_validate_json(await query(session, KEY_STATUS, b"", timeout))
    except (QueryFailed, ValidationError) as e:
        log.info("no simulator status: %s", e)
        return None


class MirrorSite:
    """A `SiteMap` over a `MapMirror` (it reads the mirror as it is now)."""

    def __init__(self, mirror: MapMirror):
        self.mirror = mirror
        self._seen: tuple[str, int] | None = None
        self._version = 0
        self._terrain_key = 0
        self._routes: OrderedDict[tuple[object, ...], float] = OrderedDict()
        self._blocked: list[list[bool]] | None = None

    @property
    def version(self) -> int:
        """Changes when the terrain, the coverage or the lander changed."""
        return self._refresh()

    def _refresh(self) -> int:
        m = self.mirror
        if self._seen != (m.feed, m.seq):
            self._seen = (m.feed, m.seq)
            terrain = m.layers.get("terrain")
            coverage = m.layers.get("coverage")
            tkey = hash(terrain.tobytes()) if terrain is not None else 0
            if tkey != self._terrain_key:
                self._terrain_key = tkey
                self._blocked = None
            ckey = hash(coverage.tobytes()) if coverage is not None else 0
            self._version = hash((tkey, ckey, self.home()))
        return self._version

    def _cell(self, layer: str, x: float, y: float) -> int | None:
        grid = self.mirror.layers.get(layer)
        ij = self.mirror.cell_of(x, y)
        if grid is None or ij is None:
            return None
        return int(grid[ij])

    def covered(self, x: float, y: float) -> bool | None:
        v = self._cell("coverage", x, y)
        return None if v is None else v > 0

    def passable(self, x: float, y: float) -> bool | None:
        v = self._cell("terrain", x, y)
        return None if v is None or v == T_UNKNOWN else v != T_ROCK

    def explored(self, x: float, y: float) -> bool | None:
        v = self._cell("terrain", x, y)
        return None if v is None else v != T_UNKNOWN

    def home(self) -> Point | None:
        objects = self.mirror.objects
        return (objects.lander.x, objects.lander.y) if objects is not None else None

    # -- routes --------------------------------------------------------------------
    def route_length(self, a: Point, b: Point) -> float:
        straight = math.dist(a, b)
        meta = self.mirror.meta
        ca, cb = self.mirror.cell_of(*a), self.mirror.cell_of(*b)
        if meta is None or ca is None or cb is None or "terrain" not in self.mirror.layers:
            return straight
        self._refresh()  # the terrain key
        key = (self._terrain_key, ca, cb)
        if key in self._routes:
            self._routes.move_to_end(key)
            return self._routes[key] if self._routes[key] >= 0 else straight
        found = self._route(ca, cb, straight, meta.cell)
        self._routes[key] = found
        while len(self._routes) > ROUTES_KEPT:
            self._routes.popitem(last=False)
        return found if found >= 0 else straight

    def _route(
        self, ca: tuple[int, int], cb: tuple[int, int], straight: float, cell: float
    ) -> float:
        """-1: the straight line is clear; else the grid route's metres (inf: none)."""
        blocked = self._grid()
        if blocked[cb[0]][cb[1]]:
            return math.inf
        if self._clear(blocked, ca, cb):
            return -1.0
        return _astar(blocked, ca, cb) * cell

    def _grid(self) -> list[list[bool]]:
        if self._blocked is None:
            terrain = self.mirror.layers["terrain"]
            self._blocked = (terrain == T_ROCK).tolist()
        return self._blocked

    @staticmethod
    def _clear(blocked: list[list[bool]], ca: tuple[int, int], cb: tuple[int, int]) -> bool:
        n = max(abs(cb[0] - ca[0]), abs(cb[1] - ca[1])) * 2 + 1
        for k in range(1, n + 1):
            i = round(ca[0] + (cb[0] - ca[0]) * k / n)
            j = round(ca[1] + (cb[1] - ca[1]) * k / n)
            if blocked[i][j]:
                return False
        return True


def _astar(blocked: list[list[bool]], a: tuple[int, int], b: tuple[int, int]) -> float:
    """Cells of the shortest 8-connected way from a to b (inf: none)."""
    h, w = len(blocked), len(blocked[0])

    def guess(i: int, j: int) -> float:
        di, dj = abs(i - b[0]), abs(j - b[1])
        return max(di, dj) + (SQRT2 - 1) * min(di, dj)

    best = {a: 0.0}
    todo = [(guess(*a), 0.0, a)]
    steps = [(di, dj, SQRT2 if di and dj else 1.0) for di in (-1, 0, 1) for dj in (-1, 0, 1)]
    while todo:
        _, cost, (i, j) = heapq.heappop(todo)
        if (i, j) == b:
            return cost
        if cost > best.get((i, j), math.inf):
            continue
        for di, dj, step in steps:
            ni, nj = i + di, j + dj
            if not (0 <= ni < h and 0 <= nj < w) or blocked[ni][nj] or (di == dj == 0):
                continue
            if di and dj and (blocked[i][nj] or blocked[ni][j]):
                continue  # no corner cutting
            c = cost + step
            if c < best.get((ni, nj), math.inf):
                best[(ni, nj)] = c
                heapq.heappush(todo, (c + guess(ni, nj), c, (ni, nj)))
    return math.inf
