"""What the ground knows of the site: only what the robots reported over the
link (the map feed and the sim status show it, `backend.protocol.mapfeed`).

Each piece of news a robot sends is a typed message (`News`) that says what
it changes here once it arrives (sim/downlink.py carries it); the ground keeps
typed records, the map feed's models where there is one.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from backend.protocol import mapfeed as mf
from sim.objects import BoxState


@dataclass(frozen=True)
class StoneReport:
    """A stone as a robot reported it (`Stone.public()`); `v` orders reports."""

    id: str
    rss: str
    x: float
    y: float
    score: float | None
    state: str  # hidden | identified | carried | ground | delivered
    holder: str | None
    v: int = 0

    @classmethod
    def of(cls, info: Mapping[str, Any]) -> StoneReport:
        return cls(**{k: info[k] for k in cls.__dataclass_fields__ if k in info})

    def item(self) -> mf.StoneItem | None:
        """On the map once it is identified (a hidden stone is nobody's news)."""
        if self.state == "hidden":
            return None
        return mf.StoneItem(
            id=self.id,
            rss=self.rss,
            x=self.x,
            y=self.y,
            score=self.score,
            state=self.state,  # type: ignore[arg-type]  # not hidden: one of the item's
            holder=self.holder,
        )


@dataclass(frozen=True)
class RobotState:
    """What a robot reports about itself with its news (the ground's record of
    it, once heard), and its truth for evaluation."""

    x: float
    y: float
    z: float
    yaw: float
    battery: float
    link: float
    airborne: bool
    docked: bool
    box: str | None
    stones: list[str]
    activity: str | None
    result: str
    odometer_m: float
    sim_seconds: float
    heard_at: float


class GroundView:
    """The ground's records: explored cells, regions, stones, boxes, deliveries
    and each robot as last heard; `version` counts changes of the objects."""

    def __init__(
        self, shape: tuple[int, int], boxes: Mapping[str, BoxState], lander: mf.LanderItem
    ):
        self.lander = lander  # the landmark everyone knows from the start, like its boxes
        self.explored = np.zeros(shape, dtype=bool)
        self.rss: dict[str, mf.RssItem] = {}
        self.stones: dict[str, StoneReport] = {}
        self.boxes: dict[str, mf.BoxItem] = {n: box_item(b.public()) for n, b in boxes.items()}
        self.deliveries: dict[str, mf.Delivery] = {}  # stone id -> its delivery
        self.robots: dict[str, RobotState] = {}  # name -> state as last heard
        self.version = 0

    # ------------------------------------------------------------ what arrives

    def learn_cells(self, cells: np.ndarray) -> None:
        self.explored.ravel()[cells] = True

    def learn_robot(self, name: str, state: RobotState) -> None:
        self.robots[name] = state

    def learn_rss(self, item: mf.RssItem) -> None:
        """A region report over what was known: a top score once revealed stays
        (a later report without it, e.g. another robot discovering it, keeps it)."""
        old = self.rss.get(item.rss)
        if item.top_score is None and old is not None:
            item = item.model_copy(update={"top_score": old.top_score})
        self.rss[item.rss] = item
        self.version += 1

    def learn_stone(self, report: StoneReport) -> None:
        old = self.stones.get(report.id)
        if old is not None and report.v < old.v:
            return  # a robot's older news of the stone (e.g. back in range only now)
        self.stones[report.id] = report
        self.version += 1

    def learn_box(self, item: mf.BoxItem) -> None:
        self.boxes[item.box] = item
        self.version += 1

    def learn_delivery(self, item: mf.Delivery) -> None:
        self.deliveries[item.stone] = item
        self.version += 1

    # ------------------------------------------------------------ what it shows

    @property
    def score(self) -> float:
        """The score as the ground knows it: the deliveries robots reported."""
        return round(sum(d.score for d in self.deliveries.values()), 6)

    def layers(self, terrain: np.ndarray, coverage: np.ndarray) -> dict[str, np.ndarray]:
        """The map feed's layers: the terrain where explored (its codes are the
        feed's), the link quality everywhere (coverage is the lander's plan)."""
        known = np.where(self.explored, terrain, mf.T_UNKNOWN).astype(np.uint8)
        cov = np.where(coverage > 0, np.maximum(1, np.rint(coverage * 255)), 0).astype(np.uint8)
        return {"terrain": known, "coverage": cov}

    def objects(self) -> mf.MapObjects:
        """The map feed's objects, as the ground knows them."""
        stones = (self.stones[k].item() for k in sorted(self.stones))
        return mf.MapObjects(
            lander=self.lander,
            boxes=[self.boxes[k] for k in sorted(self.boxes)],
            rss=[self.rss[k] for k in sorted(self.rss)],
            stones=[s for s in stones if s is not None],
            score=self.score,
        )


def box_item(info: Mapping[str, Any]) -> mf.BoxItem:
    return mf.BoxItem(**{k: v for k, v in info.items() if k in mf.BoxItem.model_fields})


def rss_item(info: Mapping[str, Any]) -> mf.RssItem:
    return mf.RssItem(**{k: v for k, v in info.items() if k in mf.RssItem.model_fields})


# ---------------------------------------------------------------- news


class News(Protocol):
    """Something a robot tells the ground: what it changes there on arrival."""

    def reach(self, ground: GroundView) -> None: ...


@dataclass(frozen=True)
class CellsSeen:
    cells: np.ndarray  # flat indices of cells the robot explored

    def reach(self, ground: GroundView) -> None:
        ground.learn_cells(self.cells)


@dataclass(frozen=True)
class RobotHeard:
    name: str
    state: RobotState

    def reach(self, ground: GroundView) -> None:
        ground.learn_robot(self.name, self.state)


@dataclass(frozen=True)
class RegionSeen:
    item: mf.RssItem

    def reach(self, ground: GroundView) -> None:
        ground.learn_rss(self.item)


@dataclass(frozen=True)
class StoneSeen:
    report: StoneReport

    def reach(self, ground: GroundView) -> None:
        ground.learn_stone(self.report)


@dataclass(frozen=True)
class BoxSeen:
    item: mf.BoxItem

    def reach(self, ground: GroundView) -> None:
        ground.learn_box(self.item)


@dataclass(frozen=True)
class Delivered:
    item: mf.Delivery

    def reach(self, ground: GroundView) -> None:
        ground.learn_delivery(self.item)
