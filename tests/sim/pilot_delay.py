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

- **ideal_chosen_on_board** (contingencies + precedence + places chosen on
  board): the whole mission in the first uplink. The two regions and the
  Wi-Fi box's spot are markers chosen on board: the robots choose them
  from Ardea's survey (asked robot to robot once Ardea is back in coverage)
  with the rule ideal_on_board's operator follows on the ground (the closest
  pair of the largest group beyond the lander's coverage), agree robot to
  robot and report the places; the rest is ideal_on_board's plan.

Robots' questions are on and nobody answers them: a question applies its
default on board at its answer_within (bench/pilot_study.py lists those asked).
"""

from __future__ import annotations

import math
from typing import Any

from backend.core.model import ChooseRule, Policies, Pose, PoseMarker, Position, PositionMarker
from backend.core.ops import AddBarrier, AddSkill, MarkerAdd

from .pilot import (
    Operator,
    Region,
    _pose,
    best_cluster,
    explore_near,
    explore_with_all_three,
    ideal,
    relay_spot,
    survey_from_the_air,
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


# ---------------------------------------------------------------- chosen on board

SURVEYOR = "ardea"  # the robot the rovers ask for the survey's regions
# the places the robots choose (markers chosen on board): (name, kind, rule)
CHOSEN = (
    ("RELAY", "pose", ChooseRule(place="relay", ask=[SURVEYOR])),
    ("R1-near", "pose", ChooseRule(rank=1, place="approach", ask=[SURVEYOR])),
    ("R1", "position", ChooseRule(rank=1, place="region", ask=[SURVEYOR])),
    ("R2-near", "pose", ChooseRule(rank=2, place="approach", ask=[SURVEYOR])),
    ("R2", "position", ChooseRule(rank=2, place="region", ask=[SURVEYOR])),
)

Bound = tuple[str, dict[str, Any], dict[str, str], Policies]  # skill, params, bindings


async def ideal_chosen_on_board(op: Operator) -> None:
    """The whole mission in the first uplink: the robots choose the two
    regions (the closest pair beyond the lander's coverage, from Ardea's
    survey, asked on board) and the Wi-Fi box's spot themselves, agreeing
    robot to robot; the rest is ideal_on_board's plan, bound to those places."""
    await _chosen_markers(op)
    (op.shelved,) = await op.do("lander", ("load_box", {"box": "wifi_box_1", "slot": 2}))
    await survey_from_the_air(op)
    lru1 = [await explore_near(op, "lru1", "east", 200.0)]
    lru1 += await op.do("lru1", ("recharge", {"target_level": 0.95}))
    lru2 = [await explore_near(op, "lru2", "west", 100.0)]
    lru2 += await op.do(
        "lru2",
        ("drive_to", {"goal": _pose((3.0, -2.0)), "speed": 1.0}),
        ("recharge", {"target_level": 0.95}),
    )
    regions = (("R1", "R1-near"), ("R2", "R2-near"))
    lru1 += await _bound(op, "lru1", *(s for g in regions for s in _chosen_visit(*g, "lru2")))
    lru2 += await _bound(
        op,
        "lru2",
        (
            "deploy_wifi_box",
            {"box": "wifi_box_1"},
            {"goal": "RELAY"},
            Policies(after=op.shelved, on_failure="skip"),
        ),
        *(s for g in regions for s in _chosen_visit(*g, "lru1") + [_chosen_pick(g[0])]),
        ("drive_to", {"goal": _pose((2.0, 0.0)), "speed": 1.0}, {}, Policies()),
        ("drop_stone", {}, {}, Policies()),
    )
    # lru1: explore, recharge, (drive, identify) x 2; lru2: explore, drive, recharge,
    # deploy, (drive, identify, pick) x 2, drive, drop
    for a, b in ((lru1[3], lru2[5]), (lru1[5], lru2[8])):
        await op.client.submit(AddBarrier(ids=[a, b], timeout=BARRIER_WAIT, on_timeout="continue"))
    await op.send("lru1", lru1[2:])
    await op.send("lru2", lru2[3:])
    await op.done(lru2[-1])
    m = op.client.mission
    assert m is not None
    for name, _kind, _rule in CHOSEN:
        mk = m.markers[name]
        if getattr(mk, "chosen", None) is not None:
            p = mk.pose if mk.kind == "pose" else mk.position  # type: ignore[union-attr]
            op.note(f"{name} chosen on board by {mk.chosen.robot}: ({p.x:.0f}, {p.y:.0f})")  # type: ignore[union-attr]


async def _chosen_markers(op: Operator) -> None:
    """The places to choose, each estimated at the lander until a robot chose it."""
    lx, ly = op.lander().x, op.lander().y
    for name, kind, rule in CHOSEN:
        marker: PoseMarker | PositionMarker
        if kind == "pose":
            marker = PoseMarker(pose=Pose(x=lx, y=ly), choose=rule, description="chosen on board")
        else:
            marker = PositionMarker(
                position=Position(x=lx, y=ly), choose=rule, description="chosen on board"
            )
        await op.client.submit(MarkerAdd(name=name, marker=marker))


async def _bound(op: Operator, robot: str, *steps: Bound) -> list[str]:
    ids = []
    for skill_name, params, bindings, policies in steps:
        reply = await op.client.submit(
            AddSkill(
                robot=robot, skill=skill_name, params=params, bindings=bindings, policies=policies
            )
        )
        ids.append(reply.value["id"])
    return ids


def _chosen_visit(region: str, near: str, partner: str) -> list[Bound]:
    """Drive next to the chosen region at full speed, identify with the partner
    (the library's search radius takes in a whole region); each goes on if it fails."""
    return [
        ("drive_to", {"speed": 1.0}, {"goal": near}, ON_FAILURE_GO_ON),
        ("identify_stone", {"partner": partner}, {"target": region}, ON_FAILURE_GO_ON),
    ]


def _chosen_pick(region: str) -> Bound:
    return ("pick_stone", {}, {"target": region}, ON_FAILURE_GO_ON)


DELAY_STRATEGIES = {
    "ideal_by_hand": ideal_by_hand,
    "ideal_on_board": ideal_on_board,
    "ideal_chosen_on_board": ideal_chosen_on_board,
}
