"""Points, polygons and straight paths, in site metres (stdlib only).

Polygons here are small (a marker's area: a handful of corners), so plain
Python is enough; shapely would add a compiled dependency for ~50 lines.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

Point = tuple[float, float]


def point_of(value: Any) -> Point | None:
    """(x, y) of a pose/position value ({"x": .., "y": ..}), else None."""
    if not isinstance(value, dict):
        return None
    x, y = value.get("x", 0.0), value.get("y", 0.0)
    if not isinstance(x, int | float) or not isinstance(y, int | float):
        return None
    return float(x), float(y)


def polygon_of(value: Any) -> tuple[Point, ...] | None:
    """The corners of an area value (a list of positions), else None."""
    if not isinstance(value, list) or len(value) < 3:
        return None
    corners = []
    for v in value:
        c = point_of(v)
        if c is None:
            return None
        corners.append(c)
    return tuple(corners)


def distance(a: Point, b: Point) -> float:
    return math.hypot(b[0] - a[0], b[1] - a[1])


def area(poly: Sequence[Point]) -> float:
    """Unsigned area (shoelace)."""
    s = 0.0
    for i, (x0, y0) in enumerate(poly):
        x1, y1 = poly[(i + 1) % len(poly)]
        s += x0 * y1 - x1 * y0
    return abs(s) / 2.0


def centroid(poly: Sequence[Point]) -> Point:
    """The area's centre of mass (the corners' mean for a degenerate one)."""
    a = 0.0
    cx = cy = 0.0
    for i, (x0, y0) in enumerate(poly):
        x1, y1 = poly[(i + 1) % len(poly)]
        cross = x0 * y1 - x1 * y0
        a += cross
        cx += (x0 + x1) * cross
        cy += (y0 + y1) * cross
    if abs(a) < 1e-9:
        n = len(poly)
        return sum(p[0] for p in poly) / n, sum(p[1] for p in poly) / n
    return cx / (3.0 * a), cy / (3.0 * a)


def _orient(a: Point, b: Point, c: Point) -> float:
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def _crosses(p: Point, q: Point, r: Point, s: Point) -> bool:
    """Segments pq and rs cross at a point inside both (touching does not count)."""
    d1, d2 = _orient(r, s, p), _orient(r, s, q)
    d3, d4 = _orient(p, q, r), _orient(p, q, s)
    return d1 * d2 < 0 and d3 * d4 < 0


def self_intersecting(poly: Sequence[Point]) -> bool:
    """Two edges that are not neighbours cross."""
    n = len(poly)
    edges = [(poly[i], poly[(i + 1) % n]) for i in range(n)]
    for i in range(n):
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue  # neighbours through the closing edge
            if _crosses(*edges[i], *edges[j]):
                return True
    return False


def inside(p: Point, poly: Sequence[Point]) -> bool:
    """Point in polygon (even-odd rule)."""
    x, y = p
    hit = False
    n = len(poly)
    for i in range(n):
        (x0, y0), (x1, y1) = poly[i], poly[(i + 1) % n]
        if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
            hit = not hit
    return hit


def to_polygon(p: Point, poly: Sequence[Point]) -> float:
    """Distance from p to the polygon (0 inside)."""
    if inside(p, poly):
        return 0.0
    best = math.inf
    for i, a in enumerate(poly):
        b = poly[(i + 1) % len(poly)]
        dx, dy = b[0] - a[0], b[1] - a[1]
        length2 = dx * dx + dy * dy
        t = (
            0.0
            if length2 == 0
            else max(0.0, min(1.0, ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / length2))
        )
        best = min(best, distance(p, (a[0] + t * dx, a[1] + t * dy)))
    return best


def along(a: Point, b: Point, step: float, most: int = 64) -> list[tuple[float, Point]]:
    """(fraction, point) every `step` metres from a to b, both ends included
    (at most `most` points)."""
    d = distance(a, b)
    n = max(1, min(most - 1, math.ceil(d / step) if step > 0 else 1))
    return [
        (i / n, (a[0] + (b[0] - a[0]) * i / n, a[1] + (b[1] - a[1]) * i / n)) for i in range(n + 1)
    ]


def samples(poly: Sequence[Point], per_side: int = 4) -> list[Point]:
    """Points of an area to ask a map about: a grid over its bounding box,
    kept when inside, plus its corners and centre."""
    xs = [p[0] for p in poly]
    ys = [p[1] for p in poly]
    out = [*poly, centroid(poly)]
    for i in range(per_side):
        for j in range(per_side):
            q = (
                min(xs) + (max(xs) - min(xs)) * (i + 0.5) / per_side,
                min(ys) + (max(ys) - min(ys)) * (j + 0.5) / per_side,
            )
            if inside(q, poly):
                out.append(q)
    return out
