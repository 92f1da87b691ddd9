"""The pilot study's ideal strategy at a long link delay (`missionctl sim
--link-delay 10m`, sim time): what the ground learns is one delay old, and
what it sends arrives one delay later (docs/pilot-study.md, "The ideal at a
10-minute delay").

- **ideal_by_hand** (today's policies only): the ideal operator of
  tests/sim/pilot.py as it is. Every step that depends on what a robot did
  waits for its report on the ground, then a command that takes a delay to
  arrive: the Wi-Fi box and LRU1's images once the survey's regions are on
  the map, the two best regions once LRU1's scores are; a failure would halt
  its robot until the ground retried it (two delays).
- **ideal_on_board** (contingencies + precedence): the same first uplink;
  then, once the survey's regions are on the map, the rest of the mission in
  one uplink, decided on board: LRU2's deploy starts `after` the lander
  shelved the box; at each region a barrier that gives up after 15 minutes
  (then each robot identifies alone, `continue`); every identify and pick
  goes on to the next step on a failure (`skip`), so nothing halts a robot
  out there. Without LRU1's scores (they would cost two more delays) it
  takes the two regions of the group closest together: one short trip.

Robots' questions are on and nobody answers them: a question applies its
default on board at its answer_within (bench/pilot_study.py lists those asked).
"""

from __future__ import annotations

import math
from typing import Any

from backend.core.model import Policies
from backend.core.ops import AddBarrier, AddSkill

from .pilot import (
    Operator,
    Region,
    _pose,
    best_cluster,
    explore_with_all_three,
    ideal,
    relay_spot,
)

DELAY_DEADLINE = 3 * 3600.0  # sim seconds a delayed run may take (the study's 26.8 min cannot)
BARRIER_WAIT = 15 * 60.0  # mission seconds a rover waits at a region for its partner, on board
ON_FAILURE_GO_ON = Policies(on_failure="skip")

Step = tuple[str, dict[str, Any], Policies]


def closest_pair(regions: list[Region]) -> list[Region]:
    """The two regions nearest each other: one short trip for both stones."""
    pairs = [(a.dist(b.x, b.y), a, b) for i, a in enumerate(regions) for b in regions[i + 1 :]]
    _d, a, b = min(pairs, key=lambda p: (p[0], p[1].name, p[2].name))
    return [a, b]


async def plan_with(op: Operator, robot: str, *steps: Step) -> list[str]:
    """Add skills with their policies at the end of the robot's list; their ids."""
    ids = []
    for skill_name, params, policies in steps:
        reply = await op.client.submit(
            AddSkill(robot=robot, skill=skill_name, params=params, policies=policies)
        )
        ids.append(reply.value["id"])
    return ids


async def ideal_by_hand(op: Operator) -> None:
    """The ideal operator, unchanged, at the delay (tests/sim/pilot.py `ideal`)."""
    await ideal(op)


async def ideal_on_board(op: Operator) -> None:
    """See the module docstring."""
    await explore_with_all_three(op, mind_batteries=True)
    shelve = op.shelved
    if not await op.until(lambda: best_cluster(op) is not None):
        return
    cluster = best_cluster(op)
    assert cluster is not None
    first, second = _in_order(op, closest_pair(cluster))
    cx, cy = (first.x + second.x) / 2, (first.y + second.y) / 2
    spot = relay_spot(op, (cx, cy))
    op.note(
        f"out there: {', '.join(g.name for g in cluster)}; committing {first.name} and "
        f"{second.name} (closest together), Wi-Fi box at ({spot[0]:.0f}, {spot[1]:.0f})"
    )
    lru1 = await plan_with(
        op, "lru1", *(s for g in (first, second) for s in _go_and_identify(op, g, "lru2"))
    )
    lru2 = await plan_with(
        op,
        "lru2",
        (
            "deploy_wifi_box",
            {"box": "wifi_box_1", "goal": _pose(spot)},
            Policies(after=shelve, on_failure="skip"),
        ),
        *(s for g in (first, second) for s in _go_and_identify(op, g, "lru1") + [_pick(g)]),
        ("drive_to", {"goal": _pose((2.0, 0.0)), "speed": 1.0}, Policies()),
        ("drop_stone", {}, Policies()),
    )
    # lru1: drive, identify, drive, identify; lru2: deploy, (drive, identify, pick) x 2, ...
    for a, b in ((lru1[1], lru2[2]), (lru1[3], lru2[5])):
        await op.client.submit(AddBarrier(ids=[a, b], timeout=BARRIER_WAIT, on_timeout="continue"))
    await op.send("lru1", lru1)
    await op.send("lru2", lru2)
    await op.done(lru2[-1])


def _go_and_identify(op: Operator, region: Region, partner: str) -> list[Step]:
    """Drive next to the region at full speed (identify_stone would drive at
    cruise speed), then identify with the partner; each goes on if it fails."""
    where, radius = _pose((region.x, region.y)), min(10.0, region.radius + 1.5)
    near = {"goal": _pose(op.free_near(region.x, region.y)), "speed": 1.0}
    return [
        ("drive_to", near, ON_FAILURE_GO_ON),
        (
            "identify_stone",
            {"target": where, "search_radius": radius, "partner": partner},
            ON_FAILURE_GO_ON,
        ),
    ]


def _pick(region: Region) -> Step:
    return ("pick_stone", {"target": _pose((region.x, region.y))}, ON_FAILURE_GO_ON)


def _in_order(op: Operator, pair: list[Region]) -> list[Region]:
    """The region nearer the lander first (the relay is on the way)."""
    lx, ly = op.lander().x, op.lander().y
    return sorted(pair, key=lambda g: math.hypot(g.x - lx, g.y - ly))


DELAY_STRATEGIES = {"ideal_by_hand": ideal_by_hand, "ideal_on_board": ideal_on_board}
