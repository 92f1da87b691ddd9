"""The site as the ground knows it from the map feed (no Textual here).

The map feed carries the score the robots reported (`objects.score`); the top
bar shows it beside the mission clock (console/state/clock.py), which the same
feed sets. Without a simulator (a real fleet) there is no site line at all.
The map's info line says what is under its cursor (`here_text`), and the
cursor stays on the site (`clamp_to_site`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from backend.core.model import Marker, Mission
from backend.core.plan.geometry import inside
from backend.protocol.messages import Telemetry
from console.state.clock import MissionClock

if TYPE_CHECKING:  # the feed's module brings numpy: not needed for the console's first frame
    from backend.protocol import mapfeed as mf


@dataclass(frozen=True)
class SiteScore:
    """The latest score the robots reported."""

    score: float


def site_text(site: SiteScore, clock: MissionClock) -> str:
    """'score 1.9 · sim 0:26:48': the score as reported and the mission clock."""
    return f"score {site.score:g} · {clock.now_text()}"


# -- what is under the map's cursor ------------------------------------------------------------

# terrain cells (backend.protocol.mapfeed T_FREE, T_SLOW, T_ROCK; 0 is unknown)
GROUND = {1: "free ground", 2: "sand (slow)", 3: "rock (impassable)"}


def clamp_to_site(meta: mf.MapMeta | None, x: float, y: float) -> tuple[float, float]:
    """(x, y) moved onto the site's grid (unchanged without a map)."""
    if meta is None:
        return x, y
    half = meta.cell / 2  # the centre of an edge cell at most
    x1, y1 = meta.x0 + meta.width * meta.cell, meta.y0 + meta.height * meta.cell
    return min(max(x, meta.x0 + half), x1 - half), min(max(y, meta.y0 + half), y1 - half)


def _near(x: float, y: float, px: float, py: float, tol: float) -> bool:
    return math.hypot(x - px, y - py) <= tol


def _marker_here(mk: Marker, x: float, y: float, tol: float) -> bool:
    if mk.kind == "area":
        return inside((x, y), [(p.x, p.y) for p in mk.area])
    p = mk.pose if mk.kind == "pose" else mk.position
    return p is not None and _near(x, y, p.x, p.y, tol)


def _things_here(
    mirror: mf.MapMirror,
    mission: Mission | None,
    telemetry: dict[str, Telemetry],
    x: float,
    y: float,
    tol: float,
) -> list[str]:
    """Regions (with their known score), markers, robots and objects at (x, y)."""
    out = _objects_here(mirror.objects, x, y, tol) if mirror.objects is not None else []
    markers = mission.markers if mission is not None else {}
    out += [f"marker {name}" for name, mk in markers.items() if _marker_here(mk, x, y, tol)]
    out += [f"robot {r}" for r, t in telemetry.items() if _near(x, y, t.pose.x, t.pose.y, tol)]
    return out


def _objects_here(objects: mf.MapObjects, x: float, y: float, tol: float) -> list[str]:
    """The simulator's regions, lander, boxes and stones at (x, y)."""
    out = [
        f"region {r.rss} ({_score_text(r.top_score)})"
        for r in objects.rss
        if _near(x, y, r.x, r.y, r.radius)
    ]
    if _near(x, y, objects.lander.x, objects.lander.y, max(tol, objects.lander.pad_radius)):
        out.append("lander")
    out += [  # (those on the lander's shelf are the lander's)
        f"box {b.box}" for b in objects.boxes if b.where != "shelf" and _near(x, y, b.x, b.y, tol)
    ]
    return out + [f"stone {s.id}" for s in objects.stones if _near(x, y, s.x, s.y, tol)]


def _score_text(top_score: float | None) -> str:
    return f"top score {top_score:g}" if top_score is not None else "score unknown"


def here_text(
    mirror: mf.MapMirror | None,
    mission: Mission | None,
    telemetry: dict[str, Telemetry],
    x: float,
    y: float,
    tol: float,
) -> str:
    """What the map shows at (x, y), from the map feed's mirror: 'region RSS-A (top
    score 1) · marker POI-A · robot lru1 · explored: free ground · in comms coverage'
    (`tol`: metres within which a point thing counts as here, a cell of the view)."""
    if mirror is None or not mirror.ready:
        return "no map yet"
    cell = mirror.cell_of(x, y)
    if cell is None:
        return "off the site"
    terrain = int(mirror.layers["terrain"][cell])
    ground = f"explored: {GROUND[terrain]}" if terrain in GROUND else "unexplored"
    cover = mirror.layers.get("coverage")
    link = "in comms coverage" if cover is not None and cover[cell] > 0 else "no comms coverage"
    return " · ".join([*_things_here(mirror, mission, telemetry, x, y, tol), ground, link])
