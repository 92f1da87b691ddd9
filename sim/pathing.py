"""Grid geometry, path planning (A* on the terrain grid) and sweep patterns.

Pure functions on numpy arrays; no Zenoh, no asyncio. Grids are indexed
[row, col] = [y, x] with row 0 at `y0` (south) and column 0 at `x0` (west).
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Sequence
from itertools import accumulate

import numpy as np

from backend.protocol.mapfeed import T_FREE, T_ROCK, T_SLOW

# terrain codes of the world's grid: the map feed's, so the ground's layer is
# the grid itself where it is known (0 is the feed's "unknown", never a cell's)
FREE, SLOW, ROCK = T_FREE, T_SLOW, T_ROCK

SQRT2 = math.sqrt(2.0)


class GridGeom:
    """Maps site coordinates (metres) to grid cells and back."""

    def __init__(self, x0: float, y0: float, cell: float, nx: int, ny: int):
        self.x0, self.y0, self.cell, self.nx, self.ny = (
            float(x0),
            float(y0),
            float(cell),
            int(nx),
            int(ny),
        )
        self.x1 = self.x0 + self.nx * self.cell
        self.y1 = self.y0 + self.ny * self.cell
        # cell centres
        self.xs = self.x0 + (np.arange(self.nx) + 0.5) * self.cell
        self.ys = self.y0 + (np.arange(self.ny) + 0.5) * self.cell

    @property
    def shape(self) -> tuple[int, int]:
        return self.ny, self.nx

    def inside(self, x: float, y: float) -> bool:
        return self.x0 <= x < self.x1 and self.y0 <= y < self.y1

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """(row, col) of the cell holding (x, y), clipped to the grid."""
        j = int((x - self.x0) // self.cell)
        i = int((y - self.y0) // self.cell)
        return min(max(i, 0), self.ny - 1), min(max(j, 0), self.nx - 1)

    def center(self, i: int, j: int) -> tuple[float, float]:
        return float(self.xs[j]), float(self.ys[i])

    def window(self, x: float, y: float, r: float) -> tuple[slice, slice]:
        """Row and column slices of the cells whose centres may lie within r of (x, y)."""
        j0 = max(int((x - r - self.x0) // self.cell), 0)
        j1 = min(int((x + r - self.x0) // self.cell) + 1, self.nx)
        i0 = max(int((y - r - self.y0) // self.cell), 0)
        i1 = min(int((y + r - self.y0) // self.cell) + 1, self.ny)
        return slice(i0, max(i0, i1)), slice(j0, max(j0, j1))

    def disk(self, x: float, y: float, r: float) -> tuple[slice, slice, np.ndarray]:
        """(rows, cols, mask) of the cells whose centres lie within r of (x, y)."""
        rows, cols = self.window(x, y, r)
        dx = self.xs[cols] - x
        dy = self.ys[rows] - y
        mask = (dy[:, None] ** 2 + dx[None, :] ** 2) <= r * r
        return rows, cols, mask

    def polygon_mask(self, points: Sequence[tuple[float, float]]) -> np.ndarray:
        """Cells whose centres lie inside the polygon (even-odd rule)."""
        X = self.xs[None, :]
        Y = self.ys[:, None]
        inside = np.zeros(self.shape, dtype=bool)
        n = len(points)
        for k in range(n):
            xa, ya = points[k]
            xb, yb = points[(k + 1) % n]
            if ya == yb:
                continue
            crosses = (ya > Y) != (yb > Y)
            xcross = xa + (Y - ya) * (xb - xa) / (yb - ya)
            inside ^= crosses & (X < xcross)
        return inside


def segment_cells(
    geom: GridGeom, x0: float, y0: float, x1: float, y1: float
) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the cells a straight segment passes (sampled at half a cell)."""
    length = math.hypot(x1 - x0, y1 - y0)
    n = max(2, int(length / (geom.cell * 0.5)) + 2)
    t = np.linspace(0.0, 1.0, n)
    xs = x0 + (x1 - x0) * t
    ys = y0 + (y1 - y0) * t
    cols = np.clip(((xs - geom.x0) // geom.cell).astype(np.int64), 0, geom.nx - 1)
    rows = np.clip(((ys - geom.y0) // geom.cell).astype(np.int64), 0, geom.ny - 1)
    return rows, cols


def line_max(
    terrain: np.ndarray, geom: GridGeom, a: tuple[float, float], b: tuple[float, float]
) -> int:
    """Worst terrain code along the segment a-b."""
    rows, cols = segment_cells(geom, a[0], a[1], b[0], b[1])
    return int(terrain[rows, cols].max())


class NoPath(Exception):
    pass


def astar(
    terrain: np.ndarray, start: tuple[int, int], goal: tuple[int, int], slow_cost: float
) -> list[tuple[int, int]]:
    """Cheapest 8-connected cell path (time-based costs: free 1, slow `slow_cost`,
    rock impassable; no corner cutting past rocks). Raises NoPath."""
    if terrain[start] == ROCK:
        raise NoPath("the start lies in impassable terrain")
    if terrain[goal] == ROCK:
        raise NoPath("the goal lies in impassable terrain")
    cost = _crossing_costs(terrain, slow_cost)
    w = terrain.shape[1] + 2
    s = (start[0] + 1) * w + start[1] + 1
    g = (goal[0] + 1) * w + goal[1] + 1
    came = _search(cost, w, s, g)
    if came is None:
        raise NoPath("no passable route to the goal")
    return _walk_back(came, s, g, w)


def _crossing_costs(terrain: np.ndarray, slow_cost: float) -> list[float]:
    """The time to cross each cell, row by row, the grid in a ring of rock
    (0.0: impassable), so that the search needs no bounds checks."""
    ny, nx = terrain.shape
    padded = np.full((ny + 2, nx + 2), ROCK, dtype=np.uint8)
    padded[1:-1, 1:-1] = terrain
    flat = padded.ravel()
    costs: list[float] = np.where(
        flat == FREE, 1.0, np.where(flat == SLOW, slow_cost, 0.0)
    ).tolist()
    return costs


def _search(cost: list[float], w: int, s: int, g: int) -> list[int] | None:
    """A* from cell `s` to cell `g` of the padded grid (`w` cells a row):
    each cell's predecessor on the cheapest path, None when `g` is out of
    reach. (The hot loop of every rover's route: written for speed.)"""
    gi, gj = divmod(g, w)
    n = len(cost)
    best = [math.inf] * n
    came = [-1] * n
    best[s] = 0.0
    heap = [(0.0, 0.0, s)]
    straight = ((-w, 1.0), (w, 1.0), (-1, 1.0), (1, 1.0))
    # diagonal step, and the two orthogonal cells it passes between
    diagonal = ((-w - 1, -w, -1), (-w + 1, -w, 1), (w - 1, w, -1), (w + 1, w, 1))
    push, pop = heapq.heappush, heapq.heappop
    while heap:
        _f, d, u = pop(heap)
        if u == g:
            return came
        if d > best[u]:
            continue  # a stale entry
        cu = cost[u]
        for off, length in straight:
            v = u + off
            cv = cost[v]
            if cv == 0.0:
                continue
            nd = d + length * 0.5 * (cu + cv)
            if nd < best[v]:
                best[v] = nd
                came[v] = u
                vi, vj = divmod(v, w)
                hi, hj = abs(vi - gi), abs(vj - gj)
                push(heap, (nd + (hi + hj) + (SQRT2 - 2.0) * (hi if hi < hj else hj), nd, v))
        for off, a, b in diagonal:
            v = u + off
            cv = cost[v]
            if cv == 0.0 or cost[u + a] == 0.0 or cost[u + b] == 0.0:
                continue  # no squeezing diagonally between rocks
            nd = d + SQRT2 * 0.5 * (cu + cv)
            if nd < best[v]:
                best[v] = nd
                came[v] = u
                vi, vj = divmod(v, w)
                hi, hj = abs(vi - gi), abs(vj - gj)
                push(heap, (nd + (hi + hj) + (SQRT2 - 2.0) * (hi if hi < hj else hj), nd, v))
    return None


def _walk_back(came: list[int], s: int, g: int, w: int) -> list[tuple[int, int]]:
    """The path from `s` to `g` (padded cells) as (row, col) of the grid."""
    path = [g]
    while path[-1] != s:
        path.append(came[path[-1]])
    path.reverse()
    return [(c // w - 1, c % w - 1) for c in path]


def smooth(
    terrain: np.ndarray, geom: GridGeom, points: list[tuple[float, float]], codes: list[int]
) -> list[tuple[float, float]]:
    """String pulling: drop waypoints while the straight line crosses no worse
    terrain than the stretch of path it replaces (galloping search for the
    farthest such waypoint: O(log n) line checks per kept waypoint)."""
    n = len(points)
    if n <= 2:
        return list(points)
    out = [points[0]]
    k = 0
    while k < n - 1:
        run_max = list(accumulate(codes[k:], max))  # the worst code from k to each j

        def ok(j: int, k: int = k, run_max: list[int] = run_max) -> bool:
            return line_max(terrain, geom, points[k], points[j]) <= run_max[j - k]

        k = _farthest(ok, k + 1, n - 1)  # k + 1 is always fine: consecutive cells
        out.append(points[k])
    return out


def _farthest(ok: Callable[[int], bool], first: int, last: int) -> int:
    """The j in first..last up to which `ok` holds (it holds at `first`):
    steps doubling from `first` until it fails, then bisection."""
    lo, hi = _gallop(ok, first, last)
    if hi is not None:
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if ok(mid):
                lo = mid
            else:
                hi = mid
    return lo


def _gallop(ok: Callable[[int], bool], first: int, last: int) -> tuple[int, int | None]:
    """(the farthest j found where `ok` holds, the first where it fails or None)."""
    lo = first
    step = 1
    while True:
        j = min(first + step, last)
        if j == lo:
            return lo, None
        if not ok(j):
            return lo, j
        lo = j
        if j == last:
            return lo, None
        step *= 2


def plan(
    terrain: np.ndarray,
    geom: GridGeom,
    start: tuple[float, float],
    goal: tuple[float, float],
    slow_cost: float,
) -> list[tuple[float, float]]:
    """Waypoints from start to goal over the terrain (start and goal included)."""
    if not geom.inside(*goal):
        raise NoPath(
            f"the goal ({goal[0]:.1f}, {goal[1]:.1f}) is outside the site "
            f"(x {geom.x0:g}..{geom.x1:g}, y {geom.y0:g}..{geom.y1:g})"
        )
    sc = geom.cell_of(*start)
    gc = geom.cell_of(*goal)
    worst = line_max(terrain, geom, start, goal)
    if worst == FREE:
        return [start, goal]  # straight line over free ground
    cells = astar(terrain, sc, gc, slow_cost)
    pts = [geom.center(i, j) for i, j in cells]
    codes = [int(terrain[i, j]) for i, j in cells]
    pts[0] = start
    pts[-1] = goal
    return smooth(terrain, geom, pts, codes)


def path_length(points: Sequence[tuple[float, float]]) -> float:
    return sum(
        math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(points, points[1:], strict=False)
    )


class Follower:
    """Walks along a polyline by distance."""

    def __init__(self, points: Sequence[tuple[float, float]]):
        self.points = [(float(p[0]), float(p[1])) for p in points]
        self.k = 0  # current segment
        self.x, self.y = self.points[0]
        self.total = path_length(self.points)
        self.done = 0.0
        self.heading = 0.0
        if len(self.points) > 1:
            a, b = self.points[0], self.points[1]
            self.heading = math.atan2(b[1] - a[1], b[0] - a[0])

    @property
    def finished(self) -> bool:
        return self.k >= len(self.points) - 1

    @property
    def remaining(self) -> float:
        return max(0.0, self.total - self.done)

    def next_point(self) -> tuple[float, float]:
        return self.points[min(self.k + 1, len(self.points) - 1)]

    def advance(self, distance: float) -> float:
        """Move up to `distance` metres; returns how far it went."""
        moved = 0.0
        while distance > 1e-9 and not self.finished:
            bx, by = self.points[self.k + 1]
            seg = math.hypot(bx - self.x, by - self.y)
            if seg > 1e-9:
                self.heading = math.atan2(by - self.y, bx - self.x)
            if seg <= distance:
                self.x, self.y = bx, by
                self.k += 1
                distance -= seg
                moved += seg
            else:
                f = distance / seg
                self.x += (bx - self.x) * f
                self.y += (by - self.y) * f
                moved += distance
                distance = 0.0
        self.done += moved
        return moved


def lawnmower(
    polygon: Sequence[tuple[float, float]], spacing: float, start: tuple[float, float]
) -> list[tuple[float, float]]:
    """Boustrophedon sweep of a polygon: lanes along x, `spacing` apart, starting
    with the lane and end nearest to `start`."""
    ys = [p[1] for p in polygon]
    ylo, yhi = min(ys), max(ys)
    height = yhi - ylo
    lanes_n = max(1, int(math.ceil(height / spacing)))
    step = height / lanes_n if lanes_n else 0.0
    lanes: list[tuple[float, float, float]] = []  # (y, xa, xb)
    for k in range(lanes_n):
        y = ylo + step * (k + 0.5) if height > 0 else ylo
        xs = _crossings(polygon, y)
        for a, b in zip(xs[0::2], xs[1::2], strict=False):
            inset = min(spacing * 0.5, (b - a) / 2)
            lanes.append((y, a + inset, b - inset))
    if not lanes:
        return [(start[0], start[1])]
    # start from the lane nearest to `start`: sweep bottom-up or top-down
    if abs(lanes[-1][0] - start[1]) < abs(lanes[0][0] - start[1]):
        lanes.reverse()
    return _mow(lanes, start[0])


def _crossings(polygon: Sequence[tuple[float, float]], y: float) -> list[float]:
    """Where the line at height `y` crosses the polygon's edges, west to east."""
    n = len(polygon)
    xs: list[float] = []
    for e in range(n):
        xa, ya = polygon[e]
        xb, yb = polygon[(e + 1) % n]
        if ya == yb:
            continue
        if (ya > y) != (yb > y):
            xs.append(xa + (y - ya) * (xb - xa) / (yb - ya))
    xs.sort()
    return xs


def _mow(lanes: list[tuple[float, float, float]], x_now: float) -> list[tuple[float, float]]:
    """The lanes in order, each driven from its end nearest to where the last one ended."""
    out: list[tuple[float, float]] = []
    for y, a, b in lanes:
        if abs(a - x_now) <= abs(b - x_now):
            out += [(a, y), (b, y)]
            x_now = b
        else:
            out += [(b, y), (a, y)]
            x_now = a
    return out
