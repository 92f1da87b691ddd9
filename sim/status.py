"""The simulator's status in two views (wire models in backend.protocol.mapfeed).

- `ground_status`: what the ground knows, from what the robots reported over the
  link (regions, top scores, deliveries and the score, each robot as last heard).
  This is what the operator, the live publication and `missionctl sim-status` get.
- `truth`: the world as it is (every region and stone, where each robot really is,
  robot-to-robot exchanges, the referee's log): evaluation only
  (`missionctl sim-status --truth`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import asdict
from typing import Any

from backend.protocol import mapfeed as mf
from sim.comms import CommsWindow
from sim.world import World

RECENT_EVENTS = 15
RECENT_EXCHANGES = 10


def ground_status(
    world: World, *, speed: float, link_delay: float, window: CommsWindow | None = None
) -> mf.SimStatus:
    w = world
    ground = w.ground
    deliveries = sorted(ground.deliveries.values(), key=lambda d: (d.sim_time, d.stone))
    return mf.SimStatus(
        world=w.spec.name,
        seed=w.seed,
        speed=speed,
        link_delay_s=link_delay,
        comms_window=mf.CommsWindowSpec(**asdict(window)) if window is not None else None,
        sim_time=round(w.now(), 1),
        score=ground.score,
        delivered=deliveries,
        rss_found=sorted(ground.rss),
        top_scores={
            n: float(r.top_score) for n, r in sorted(ground.rss.items()) if r.top_score is not None
        },
        explored=round(w.explored_fraction(ground=True), 4),
        robots=_heard_robots(w),
    )


def _heard_robots(w: World) -> dict[str, mf.RobotStatus]:
    """Each robot as the ground last heard it (never heard: the ground knows only its name)."""
    robots = {}
    for r in w.robots.values():
        heard = w.ground.robots.get(r.name)
        if heard is not None:
            robots[r.name] = mf.RobotStatus(
                name=r.name, type=r.type, kind=r.kind, in_range=w.in_range(r), **asdict(heard)
            )
    return robots


def truth(
    world: World, *, exchanges: Mapping[str, int], exchange_log: Iterable[str]
) -> mf.SimTruth:
    w = world
    return mf.SimTruth(
        score=round(w.score, 4),
        delivered=list(w.delivered),
        regions=[
            mf.RegionTruth(
                rss=r.name,
                x=r.x,
                y=r.y,
                radius=r.radius,
                max_score=r.max_score,
                stones=sum(1 for s in r.stones if w.stones[s].state == "hidden"),
                found_by=sorted(r.found_by),
            )
            for r in w.rss.values()
        ],
        stones=[_stone(s.public()) for s in w.stones.values()],
        explored=round(w.explored_fraction(), 4),
        robots={r.name: _robot(w, r) for r in w.robots.values()},
        exchanges=dict(exchanges),
        exchange_log=list(exchange_log)[-RECENT_EXCHANGES:],
        events=list(w.events)[-RECENT_EVENTS:],
    )


def _stone(info: dict[str, Any]) -> mf.StoneTruth:
    return mf.StoneTruth(**{k: v for k, v in info.items() if k in mf.StoneTruth.model_fields})


def _robot(w: World, r: Any) -> mf.RobotStatus:
    state = w.robot_state(r)
    return mf.RobotStatus(
        name=r.name,
        type=r.type,
        kind=r.kind,
        in_range=w.in_range(r),
        knows={
            "rss": len(r.knowledge.rss),
            "stones": len(r.knowledge.stones),
            "boxes": len(r.knowledge.boxes),
        },
        **asdict(state),
    )
