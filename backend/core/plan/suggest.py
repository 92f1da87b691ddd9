"""Allocation hints (issue 30): which robots can do a skill, or take over a
selection of skills, ranked by the forecast — when each would end with them,
how long it would be out of comms coverage doing them, and the battery it
would have left.

For each robot in service, the skills are given to it in a copy of the
mission (the reassign rule decides which can move and why the others
cannot; a skill named by its library name is a new one at the end of its
plan), and the copy is forecast. Robots that can take everything come
first, then those that take the most (one that takes less ends earlier for
that alone); the earliest end first; between equal ends, the one out of
coverage for less time (it can be told what to do meanwhile), then the most
battery left.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from backend.core import events as ev
from backend.core.library import Library, default_value
from backend.core.model import Mission, SkillInstance
from backend.core.ops import Reassign
from backend.core.plan.forecast import Forecast, Forecaster
from backend.core.plan.inputs import PlanInputs
from backend.core.rules import reassign as reassigning
from backend.core.rules.base import Offers, Refusal, Rules

PROBE_ID = "suggested-1"  # the new skill of a hint asked by skill name


@dataclass(frozen=True)
class Suggestion:
    """One robot's bid: what it could take, why not the rest, and the forecast."""

    robot: str
    moved: tuple[str, ...]
    refused: dict[str, str] = field(default_factory=dict)
    end: float | None = None  # its last skill's predicted end with them (None: never)
    battery_end: float | None = None
    battery_assumed: bool = False  # no telemetry: a full battery was assumed
    # wall seconds out of comms coverage doing them, the drives to them
    # included (None: no site map, unknown)
    out_of_coverage_s: float | None = None

    @property
    def capable(self) -> bool:
        return bool(self.moved) and not self.refused

    def rank(self) -> tuple[bool, int, float, float, float]:
        end = self.end if self.end is not None else math.inf
        battery = -(self.battery_end if self.battery_end is not None else 0.0)
        return (not self.capable, -len(self.moved), end, self.out_of_coverage_s or 0.0, battery)


class Manifests:
    """What each robot offers as its last manifest said (robot -> skill ->
    version), for a client that knows the fleet but is not the server."""

    def __init__(self, skills: Mapping[str, Mapping[str, str]]) -> None:
        self._skills = skills

    def offered(self, robot: str) -> Mapping[str, str] | None:
        return self._skills.get(robot)

    @classmethod
    def of(cls, fleet: Mapping[str, Any]) -> Manifests:
        """From a fleet's entries (robot -> an object with a `manifest` or None)."""
        return cls({n: dict(r.manifest.skills) for n, r in fleet.items() if r.manifest is not None})


def suggest(
    mission: Mission,
    library: Library,
    inputs: PlanInputs,
    what: list[str],
    offers: Offers | None = None,
) -> list[Suggestion]:
    """The robots in service ranked for `what`: skill ids, or one skill name."""
    if len(what) == 1 and mission.find(what[0]) is None and what[0] in library.skills:
        return _ranked(_by_name(mission, library, inputs, what[0], offers))
    return _ranked(_by_ids(mission, library, inputs, _known(mission, what), offers))


def taken_words(moved: int, refused: int) -> str:
    """Why a robot ranks where it does, first: 'takes 3 of 4, ' or 'takes all 3, '
    ('' for a single skill: its row is the robot taking it)."""
    if refused:
        return f"takes {moved} of {moved + refused}, "
    return f"takes all {moved}, " if moved > 1 else ""


def _known(mission: Mission, ids: list[str]) -> list[str]:
    missing = [sid for sid in ids if mission.find(sid) is None]
    if missing:
        raise Refusal("unknown_skill", f"no skill with id or library name {', '.join(missing)}")
    return ids


def _by_ids(
    mission: Mission, library: Library, inputs: PlanInputs, ids: list[str], offers: Offers | None
) -> list[Suggestion]:
    """Each robot in service but the skills' only owner, given them all."""
    owners = {found[0] for sid in ids if (found := mission.find(sid)) is not None}
    forecaster = Forecaster(library)
    return [
        _bid(mission, library, inputs, forecaster, ids, robot, offers)
        for robot, spec in mission.robots.items()
        if not spec.retired and owners != {robot}
    ]


def _ranked(bids: list[Suggestion]) -> list[Suggestion]:
    return sorted(bids, key=Suggestion.rank)


def _bid(
    mission: Mission,
    library: Library,
    inputs: PlanInputs,
    forecaster: Forecaster,
    ids: list[str],
    robot: str,
    offers: Offers | None,
) -> Suggestion:
    rules = Rules(mission, library, offers=offers)
    try:
        change = reassigning.reassign(rules, Reassign(ids=ids, to=robot))
    except Refusal as r:
        return Suggestion(robot, (), _reasons(rules, ids, robot, r.message))
    copy = mission.copy_deep()
    copy = ev.apply_events(copy, ev.EventBatch(revision=copy.revision + 1, events=change.events))
    return _forecast(
        forecaster, copy, inputs, robot, tuple(change.value["moved"]), change.value["refused"]
    )


def _reasons(rules: Rules, ids: list[str], robot: str, said: str) -> dict[str, str]:
    out: dict[str, str] = {}
    waiting = reassigning.waiters(rules.mission)
    for sid in ids:
        owner, _, s = rules.skill(sid)
        out[sid] = reassigning.why_not(rules, s, owner, robot, waiting) or said
    return out


def _forecast(
    forecaster: Forecaster,
    mission: Mission,
    inputs: PlanInputs,
    robot: str,
    moved: tuple[str, ...],
    refused: Mapping[str, str],
    probed: tuple[str, ...] = (),
) -> Suggestion:
    forecast = forecaster.forecast(mission, inputs)
    fc = forecast.robots.get(robot)
    if fc is None:
        return Suggestion(robot, moved, dict(refused))
    out = _out_of_coverage(forecast, robot, probed or moved, inputs)
    return Suggestion(robot, moved, dict(refused), fc.end, fc.battery_end, fc.battery_assumed, out)


def _out_of_coverage(
    forecast: Forecast, robot: str, ids: tuple[str, ...], inputs: PlanInputs
) -> float | None:
    """Wall seconds the robot spends out of comms coverage doing the skills, by
    the forecast (None: no site map, unknown)."""
    if inputs.site is None:
        return None
    skills = [f for f in forecast.robot_skills(robot) if f.id in ids]
    return sum(b - a for f in skills for a, b in f.out_of_coverage)


def _by_name(
    mission: Mission, library: Library, inputs: PlanInputs, skill: str, offers: Offers | None
) -> list[Suggestion]:
    """A new `skill` (library defaults) at the end of each robot's plan."""
    spec = library.skills[skill]
    params = {k: default_value(p) for k, p in spec.params.items() if p.default is not None}
    probe = SkillInstance(id=PROBE_ID, skill=skill, params=params)
    forecaster = Forecaster(library)
    out: list[Suggestion] = []
    for robot, rspec in mission.robots.items():
        if rspec.retired:
            continue
        why = _cannot_run(library, offers, robot, rspec.type, skill)
        if why is not None:
            out.append(Suggestion(robot, (), {skill: why}))
            continue
        copy = mission.copy_deep()
        copy.tasks.setdefault(robot, []).append(probe.model_copy())
        out.append(_forecast(forecaster, copy, inputs, robot, (skill,), {}, (PROBE_ID,)))
    return out


def _cannot_run(
    library: Library, offers: Offers | None, robot: str, robot_type: str, skill: str
) -> str | None:
    spec = library.skill_for(robot_type, skill)
    if spec is None:
        return f"{robot} ({robot_type}) has no skill '{skill}'"
    offered = offers.offered(robot) if offers is not None else None
    why = reassigning.incompatible(offered, skill, spec.version) if offered is not None else None
    return f"{robot} {why}" if why else None
