"""Markers on the map, as the map screen edits them: where a marker is, a new
marker at the cursor, a moved marker's value, which parameters of a skill a
marker fits, and which markers the plan uses. Textual-free."""

from __future__ import annotations

import re
from typing import Any

from backend.core.model import (
    FINISHED,
    AreaMarker,
    Mission,
    Pose,
    PoseMarker,
    Position,
    PositionMarker,
    SkillInstance,
    Status,
)
from backend.core.params import marker_value
from console.state.model import ConsoleModel


def centroid(pts: list[tuple[float, float]]) -> tuple[float, float]:
    return sum(p[0] for p in pts) / len(pts), sum(p[1] for p in pts) / len(pts)


def marker_point(mk: Any) -> tuple[float, float]:
    """Where a marker is: a pose's or position's point, an area's centroid."""
    if mk.kind == "pose":
        return mk.pose.x, mk.pose.y
    if mk.kind == "position":
        return mk.position.x, mk.position.y
    return centroid([(p.x, p.y) for p in mk.area])


def free_name(mission: Mission | None) -> str:
    """The first of M1, M2, … that no marker has."""
    taken = set(mission.markers) if mission else set()
    i = 1
    while f"M{i}" in taken:
        i += 1
    return f"M{i}"


def new_marker(kind: str, x: float, y: float, heading: float, mpp: float) -> Any:
    """A marker of `kind` at (x, y): a pose with the heading, a position, or
    a square area around the point (at least 5 m, 4 pixels of the view)."""
    if kind == "pose":
        return PoseMarker(pose=Pose(x=x, y=y, yaw=round(heading, 3)))
    if kind == "position":
        return PositionMarker(position=Position(x=x, y=y))
    r = max(5.0, 4 * mpp)
    return AreaMarker(
        area=[
            Position(x=x - r, y=y - r),
            Position(x=x + r, y=y - r),
            Position(x=x + r, y=y + r),
            Position(x=x - r, y=y + r),
        ]
    )


def moved_value(mk: Any, x: float, y: float, heading: float) -> Any:
    """A marker's value at (x, y): a pose takes the heading, an area moves whole."""
    if mk.kind == "pose":
        return Pose(x=x, y=y, z=mk.pose.z, yaw=round(heading, 3))
    if mk.kind == "position":
        return Position(x=x, y=y, z=mk.position.z)
    cx, cy = centroid([(p.x, p.y) for p in mk.area])
    return [Position(x=round(p.x + x - cx, 2), y=round(p.y + y - cy, 2), z=p.z) for p in mk.area]


def picked_value(kind: str, x: float, y: float, heading: float) -> dict[str, float]:
    """A pose or position parameter's value at (x, y) (a pose takes the heading)."""
    value = {"x": x, "y": y, "z": 0.0}
    if kind == "pose":
        value |= {"roll": 0.0, "pitch": 0.0, "yaw": round(heading, 3)}
    return value


def followers(mission: Mission, name: str) -> list[str]:
    """Idle skills bound to the marker: they follow it when it moves."""
    return [
        s.id
        for task in mission.tasks.values()
        for s in task
        if s.status == Status.IDLE and name in s.bindings.values()
    ]


def bind_choices(spec: Any, mk: Any) -> tuple[list[str], list[str]]:
    """(parameters the marker can give a value, its own kind first — the
    server's own rule: a pose marker fits a position too —, marker-typed
    parameters that may name it)."""
    fits = sorted(
        (p for p, ps in spec.params.items() if marker_value(ps, mk)[1] is None),
        key=lambda p: spec.params[p].type != mk.kind,
    )
    names = [
        p
        for p, ps in spec.params.items()
        if ps.type == "marker" and (not ps.marker_kinds or mk.kind in ps.marker_kinds)
    ]
    return fits, names


_USE_RANK = {"unused": 0, "bound": 1, "active": 2}


def marker_use(model: ConsoleModel) -> dict[str, str]:
    """marker -> 'active' (a skill on a robot uses it), 'bound' (idle skills
    only) or 'unused'."""
    m = model.mission
    if m is None:
        return {}
    use = dict.fromkeys(m.markers, "unused")
    for s in (s for task in m.tasks.values() for s in task if s.status not in FINISHED):
        how = "bound" if s.status == Status.IDLE else "active"
        for name in _markers_named(s, use):  # the busiest use wins
            use[name] = max(use[name], how, key=_USE_RANK.__getitem__)
    return use


def _markers_named(s: SkillInstance, markers: dict[str, str]) -> set[str]:
    """The markers a skill is bound to or names in a (marker-typed) parameter."""
    named = set(s.bindings.values()) | {v for v in s.params.values() if isinstance(v, str)}
    return named & markers.keys()


def relabel(label: str, old: str | None, new: str | None) -> str | None:
    """A label that names marker `old` ("drive to POI-A"), naming `new`
    instead; None when it does not name `old` (or nothing changes)."""
    if not old or not new or old == new:
        return None
    pattern = re.compile(rf"(?<![\w-]){re.escape(old)}(?![\w-])")
    if not pattern.search(label):
        return None
    return pattern.sub(new, label)
