"""Robots that break and robots that join during a simulation (issue 30):

    missionctl sim ... --break lru1@12m          lru1 stops responding at 12 sim-minutes
    missionctl sim ... --break lru2@20m:arm      lru2's manipulator fails (its arm skills fail)
    missionctl sim ... --join lru3:lru_science@15m   a new robot arrives and asks to join

Times are sim time (as --link-delay). A robot that stops responding ends its
agent (its presence goes: the server says it went offline); a joining robot
is a robot of the world that registers under its new name, so the server
announces it and an operator adds it.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
from dataclasses import dataclass
from typing import Any, Literal

from sim.comms import parse_duration

log = logging.getLogger(__name__)

# the skills a failed manipulator cannot do
ARM_SKILLS = frozenset(
    {"pick_stone", "drop_stone", "pick_payload_box", "place_payload_box", "deploy_wifi_box"}
)

How = Literal["silent", "arm"]


@dataclass(frozen=True)
class Breakdown:
    robot: str
    at: float  # sim seconds
    how: How = "silent"


@dataclass(frozen=True)
class Arrival:
    robot: str
    type: str
    at: float  # sim seconds


def _name(text: str, what: str) -> str:
    from backend.core.model import NAME_RE  # here: `missionctl --help` stays quick

    if not NAME_RE.match(text) or len(text) > 64:
        raise argparse.ArgumentTypeError(
            f"{what} {text!r} must start with a letter and hold only letters, digits, '_', '-'"
        )
    return text


def parse_break(text: str) -> Breakdown:
    """`ROBOT@TIME[:silent|arm]` (argparse `type`)."""
    robot, at, rest = text.partition("@")
    if not at:
        raise argparse.ArgumentTypeError(f"--break {text!r}: expected ROBOT@TIME[:silent|arm]")
    when, _, how = rest.partition(":")
    if how not in ("", "silent", "arm"):
        raise argparse.ArgumentTypeError(
            f"--break {text!r}: '{how}' is no way to break: silent (stops responding) or arm "
            "(its manipulator fails)"
        )
    return Breakdown(_name(robot, "--break robot"), parse_duration(when), how or "silent")  # type: ignore[arg-type]


def parse_join(text: str) -> Arrival:
    """`ROBOT:TYPE@TIME` (argparse `type`)."""
    who, at, when = text.partition("@")
    robot, colon, rtype = who.partition(":")
    if not at or not colon:
        raise argparse.ArgumentTypeError(f"--join {text!r}: expected ROBOT:TYPE@TIME")
    return Arrival(_name(robot, "--join robot"), _name(rtype, "--join type"), parse_duration(when))


def _check_join(fleet: Any, j: Arrival) -> None:
    if j.robot in fleet.agents:
        raise ValueError(f"--join {j.robot}: a robot of that name is simulated already")
    if j.type not in fleet.library.robot_types:
        known = ", ".join(fleet.library.robot_types)
        raise ValueError(
            f"--join {j.robot}: the library has no robot type '{j.type}' (types: {known})"
        )
    if j.type not in fleet.world.models:
        raise ValueError(f"--join {j.robot}: the world has no model for type '{j.type}'")


class TeamEvents:
    """Breakdowns and arrivals, each done when the sim clock reaches it."""

    def __init__(self, breaks: list[Breakdown], joins: list[Arrival]) -> None:
        self.breaks = breaks
        self.joins = joins
        self.broken_arms: set[str] = set()

    def check(self, fleet: Any) -> None:
        """Refuse what cannot happen (ValueError, said in a sentence)."""
        for b in self.breaks:
            if b.robot not in fleet.agents:
                known = ", ".join(fleet.agents)
                raise ValueError(f"--break {b.robot}: not a simulated robot (robots: {known})")
        for j in self.joins:
            _check_join(fleet, j)

    def arm_failed(self, robot: str, skill: str) -> bool:
        return robot in self.broken_arms and skill in ARM_SKILLS

    async def run(self, fleet: Any) -> None:
        """One task: each event in time order (sim time), until all are done."""
        todo: list[Breakdown | Arrival] = sorted([*self.breaks, *self.joins], key=lambda e: e.at)
        for e in todo:
            wait = (e.at - fleet.now()) / fleet.speed
            if wait > 0:
                await asyncio.sleep(wait)  # the sim clock, not a synchronisation
            if isinstance(e, Breakdown):
                await self._break(fleet, e)
            else:
                await fleet.join(e.robot, e.type)
                fleet.world.log(f"{e.robot} ({e.type}) arrived and asks to join the mission")

    async def _break(self, fleet: Any, b: Breakdown) -> None:
        if b.how == "arm":
            self.broken_arms.add(b.robot)
            fleet.world.log(f"{b.robot}'s manipulator failed")
            return
        fleet.world.log(f"{b.robot} stopped responding")
        agent = fleet.agents.get(b.robot)
        if agent is not None:
            await agent.stop()
