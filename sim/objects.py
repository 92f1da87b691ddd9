"""The objects of the simulated site (regions ideal for sampling stones, stones,
payload boxes) and what one robot knows of them (its own world model)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


def _fmt(x: float, y: float) -> str:
    return f"({x:.1f}, {y:.1f})"


@dataclass
class RssState:
    name: str
    x: float
    y: float
    radius: float
    max_score: float
    stones: list[str] = field(default_factory=list)
    found_by: set[str] = field(default_factory=set)

    def sighting(self) -> dict[str, Any]:
        """What a robot that sees the region learns (its top score takes a science image)."""
        return {
            "rss": self.name,
            "x": self.x,
            "y": self.y,
            "radius": self.radius,
            "top_score": None,
        }


@dataclass
class Stone:
    id: str
    rss: str
    x: float
    y: float
    score: float | None = None  # set when identified
    state: str = "hidden"  # hidden | identified | carried | ground | delivered
    holder: str | None = None
    identified_by: tuple[str, ...] = ()
    version: int = 0  # +1 at every change: of two reports about it, the higher is newer

    def public(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "rss": self.rss,
            "x": round(self.x, 2),
            "y": round(self.y, 2),
            "score": self.score,
            "state": self.state,
            "holder": self.holder,
            "v": self.version,
        }

    def change(self, **values: Any) -> None:
        """Set some fields; the stone's version goes up (reports of it are newer)."""
        for k, v in values.items():
            setattr(self, k, v)
        self.version += 1


@dataclass
class BoxState:
    name: str
    kind: str
    where: str  # shelf | storage | ground | carried
    slot: int | None = None
    x: float = 0.0
    y: float = 0.0
    holder: str | None = None
    on: bool = False  # a deployed Wi-Fi box

    def public(self) -> dict[str, Any]:
        return {
            "box": self.name,
            "kind": self.kind,
            "where": self.where,
            "slot": self.slot,
            "x": round(self.x, 2),
            "y": round(self.y, 2),
            "holder": self.holder,
            "on": self.on,
        }


def merge_rss(old: dict[str, Any] | None, new: dict[str, Any]) -> dict[str, Any]:
    """A region report over what was known: a top score once revealed stays (a later
    report of the region without it, e.g. another robot discovering it, keeps it)."""
    merged = {**(old or {}), **new}
    if merged.get("top_score") is None and old is not None:
        merged["top_score"] = old.get("top_score")
    return merged


def newer_stone(old: dict[str, Any] | None, new: dict[str, Any]) -> bool:
    """Whether a stone report `new` is at least as recent as what was known (`old`)."""
    return old is None or int(new.get("v", 0)) >= int(old.get("v", 0))


@dataclass
class Knowledge:
    """What one robot knows about the world (its own world model)."""

    rss: dict[str, dict[str, Any]] = field(default_factory=dict)
    stones: dict[str, dict[str, Any]] = field(default_factory=dict)
    boxes: dict[str, dict[str, Any]] = field(default_factory=dict)

    def learn_rss(self, info: dict[str, Any]) -> dict[str, Any]:
        merged = merge_rss(self.rss.get(info["rss"]), info)
        self.rss[info["rss"]] = merged
        return merged

    def learn_stone(self, info: dict[str, Any]) -> bool:
        """Keep a stone report unless what the robot knows is newer; True if kept."""
        if not newer_stone(self.stones.get(info["id"]), info):
            return False
        self.stones[info["id"]] = dict(info)
        return True

    def gone_stones(self) -> dict[str, int]:
        """Stone id -> version, of the stones this robot knows cannot be picked any more."""
        return {
            sid: int(s.get("v", 0))
            for sid, s in self.stones.items()
            if s.get("state") not in ("identified", "ground")
        }
