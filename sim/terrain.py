"""The site's terrain: free, slow (sand) and impassable ground on the grid
(the map feed's codes, sim.pathing), generated from the world file and the
seed; what a cell is, and routes across it."""

from __future__ import annotations

import math

import numpy as np

from sim.errors import SimError
from sim.objects import _fmt
from sim.pathing import FREE, ROCK, SLOW, GridGeom, NoPath, line_max, plan
from sim.worldfile import WorldFile


class Terrain:
    """The grid of terrain codes and the questions asked of it."""

    def __init__(self, spec: WorldFile, geom: GridGeom, rng: np.random.Generator):
        self.spec = spec
        self.geom = geom
        self.grid = self._generate_terrain(rng)
        self.slow_cost = 1.0 / spec.terrain.slow_factor  # a slow cell takes this long to cross

    # ------------------------------------------------------------ queries

    def at(self, x: float, y: float) -> int:
        """The code at (x, y); outside the site: impassable."""
        if not self.geom.inside(x, y):
            return ROCK
        return int(self.grid[self.geom.cell_of(x, y)])

    def passable(self, x: float, y: float) -> bool:
        return self.geom.inside(x, y) and self.grid[self.geom.cell_of(x, y)] != ROCK

    def nearest_free(self, x: float, y: float, max_r: float = 10.0) -> tuple[float, float] | None:
        """Nearest passable cell centre to (x, y) within max_r, or None."""
        if self.passable(x, y):
            return x, y
        rows, cols, mask = self.geom.disk(x, y, max_r)
        ok = mask & (self.grid[rows, cols] != ROCK)
        if not ok.any():
            return None
        ii, jj = np.nonzero(ok)
        xs = self.geom.xs[cols][jj]
        ys = self.geom.ys[rows][ii]
        k = int(np.argmin((xs - x) ** 2 + (ys - y) ** 2))
        return float(xs[k]), float(ys[k])

    def straight_clear(self, a: tuple[float, float], b: tuple[float, float]) -> bool:
        return line_max(self.grid, self.geom, a, b) < ROCK

    # ------------------------------------------------------------ routes

    def route(
        self, start: tuple[float, float], goal: tuple[float, float], *, flies: bool
    ) -> list[tuple[float, float]]:
        """Waypoints for a rover (terrain-aware) or a drone (straight); SimError
        (a sentence) when there is none."""
        g = self.geom
        if flies:
            if not g.inside(*goal):
                raise SimError(f"the goal {_fmt(*goal)} is outside the site")
            return [start, goal]
        if g.inside(*goal) and self.grid[g.cell_of(*goal)] == ROCK:
            raise SimError(f"the goal {_fmt(*goal)} lies in impassable terrain (rocks)")
        try:
            return plan(self.grid, g, start, goal, self.slow_cost)
        except NoPath as e:
            raise SimError(f"no route from {_fmt(*start)} to {_fmt(*goal)}: {e}") from None

    # ------------------------------------------------------------ generation

    def _keep_clear(self) -> list[tuple[float, float, float]]:
        sp = self.spec
        out = [(c.x, c.y, c.r) for c in sp.terrain.keep_clear]
        out.append((sp.lander.x, sp.lander.y, sp.lander.pad_radius + 8.0))
        out += [(r.x, r.y, r.radius + 2.0) for r in sp.rss]
        out += [(r.x, r.y, 4.0) for r in sp.robots.values()]
        out += [(b.x, b.y, 3.0) for b in sp.boxes.values() if b.x is not None and b.y is not None]
        return out

    def _generate_terrain(self, rng: np.random.Generator) -> np.ndarray:
        g = self.geom
        t = np.full(g.shape, FREE, dtype=np.uint8)
        clear = self._keep_clear()
        s = self.spec.site

        def scatter(count: int, radius: tuple[float, float], code: int) -> None:
            for _ in range(count):
                for _try in range(30):
                    x = float(rng.uniform(s.x_min, s.x_max))
                    y = float(rng.uniform(s.y_min, s.y_max))
                    r = float(rng.uniform(*radius))
                    if all(math.hypot(x - cx, y - cy) > r + cr for cx, cy, cr in clear):
                        break
                else:
                    continue
                # a blob: one to three overlapping discs
                for k in range(int(rng.integers(1, 4))):
                    ox, oy = rng.normal(0, r * 0.5, 2) if k else (0.0, 0.0)
                    rr = r * (1.0 if k == 0 else float(rng.uniform(0.5, 0.9)))
                    rows, cols, mask = g.disk(x + float(ox), y + float(oy), rr)
                    sub = t[rows, cols]
                    if code == SLOW:
                        sub[mask & (sub == FREE)] = SLOW
                    else:
                        sub[mask] = code

        scatter(self.spec.terrain.rock_fields.count, self.spec.terrain.rock_fields.radius, ROCK)
        scatter(self.spec.terrain.sand_patches.count, self.spec.terrain.sand_patches.radius, SLOW)
        codes = {"free": FREE, "slow": SLOW, "impassable": ROCK}
        for f in self.spec.terrain.features:
            if f.circle is not None:
                rows, cols, mask = g.disk(f.circle.x, f.circle.y, f.circle.r)
                t[rows, cols][mask] = codes[f.kind]
            else:
                assert f.polygon is not None
                t[g.polygon_mask([(p.x, p.y) for p in f.polygon])] = codes[f.kind]
        # the lander's surroundings are always drivable
        rows, cols, mask = g.disk(
            self.spec.lander.x, self.spec.lander.y, self.spec.lander.pad_radius + 3.0
        )
        t[rows, cols][mask] = FREE
        self._connect(t, clear)
        return t

    def _reachable(self, t: np.ndarray) -> np.ndarray:
        """Cells reachable from the lander (4-connected flood fill, numpy)."""
        passable = t != ROCK
        reach: np.ndarray = np.zeros_like(passable)
        reach[self.geom.cell_of(self.spec.lander.x, self.spec.lander.y)] = True
        while True:
            grown = reach.copy()
            grown[1:, :] |= reach[:-1, :]
            grown[:-1, :] |= reach[1:, :]
            grown[:, 1:] |= reach[:, :-1]
            grown[:, :-1] |= reach[:, 1:]
            grown &= passable
            if (grown == reach).all():
                return reach
            reach = grown

    def _connect(self, t: np.ndarray, clear: list[tuple[float, float, float]]) -> None:
        """Carve corridors to enclosed places that must be reachable; pockets
        nobody needs become rock (the map has no unreachable islands)."""
        g = self.geom
        reach = self._reachable(t)
        lx, ly = self.spec.lander.x, self.spec.lander.y
        carved = False
        for cx, cy, _r in clear:
            if not g.inside(cx, cy):
                continue
            if not reach[g.cell_of(cx, cy)]:
                self._carve(t, (cx, cy), (lx, ly))
                carved = True
        if carved:
            reach = self._reachable(t)
        t[(t != ROCK) & ~reach] = ROCK

    def _carve(self, t: np.ndarray, a: tuple[float, float], b: tuple[float, float]) -> None:
        """Free ground at `a` and a corridor of sand from it to `b` through the
        rocks on the way (three cells wide)."""
        g = self.geom
        (cx, cy), (lx, ly) = a, b
        rows, cols, mask = g.disk(cx, cy, 1.0)
        t[rows, cols][mask] = FREE
        n = int(math.hypot(cx - lx, cy - ly) / (g.cell * 0.5)) + 2
        for k in range(n + 1):
            f = k / n
            i, j = g.cell_of(cx + (lx - cx) * f, cy + (ly - cy) * f)
            if t[i, j] == ROCK:
                t[max(i - 1, 0) : i + 2, max(j - 1, 0) : j + 2][
                    t[max(i - 1, 0) : i + 2, max(j - 1, 0) : j + 2] == ROCK
                ] = SLOW
