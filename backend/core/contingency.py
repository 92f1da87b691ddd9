"""Contingencies (policies on_failure / on_timeout) against a library and a
mission's markers: what a file or an operation may ask for, and the concrete
skills the robot gets with the sync for a fallback or a goto.

A fallback's skills must be skills of the robot's type with valid parameters;
a goto's marker must exist and the robot's type must have a drive skill: its
first skill that only travels (a duration model with a goal and a speed
parameter and no base time: drive_to, fly_to).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Literal

from backend.core.library import Library, SkillSpec, check_params
from backend.core.model import (
    Branch,
    Branches,
    Fallback,
    FallbackSkill,
    Goto,
    Policies,
    SkillInstance,
    Status,
)

Path = tuple[str | int, ...]
Problem = tuple[Path, str]
TRIGGERS: tuple[Literal["on_failure", "on_timeout"], ...] = ("on_failure", "on_timeout")


def drive_skill(lib: Library, robot_type: str) -> tuple[str, str] | None:
    """(skill, its goal parameter) a robot of this type drives (or flies) with."""
    for name in lib.skills_of(robot_type):
        spec = lib.skills.get(name)
        if spec is not None and _only_travels(spec):
            return name, str(spec.duration.goal_param)
    return None


def _only_travels(spec: SkillSpec) -> bool:
    d = spec.duration
    return bool(d.goal_param and d.speed_param and d.base_s == 0 and d.goal_param in spec.params)


def branch_skills(branch: Branch, lib: Library, robot_type: str) -> list[FallbackSkill] | str:
    """The skills a branch runs (none for halt/skip/continue), or why it cannot."""
    if isinstance(branch, Fallback):
        return list(branch.fallback)
    if isinstance(branch, Goto):
        drive = drive_skill(lib, robot_type)
        if drive is None:
            return f"robot type '{robot_type}' has no drive skill to go to marker {branch.goto}"
        return [FallbackSkill(skill=drive[0], bindings={drive[1]: branch.goto})]
    return []


def contingency_problems(
    policies: Policies,
    lib: Library,
    robot_type: str,
    markers: Mapping[str, Any],
    robots: set[str],
) -> list[Problem]:
    """Every problem of a skill's contingencies, at paths under `policies`."""
    return [
        problem
        for trigger in TRIGGERS
        for problem in _branch_problems(
            getattr(policies, trigger), trigger, lib, robot_type, markers, robots
        )
    ]


def _branch_problems(
    branch: Branch,
    trigger: str,
    lib: Library,
    robot_type: str,
    markers: Mapping[str, Any],
    robots: set[str],
) -> list[Problem]:
    here: Path = ("policies", trigger)
    if isinstance(branch, Goto) and branch.goto not in markers:
        known = ", ".join(sorted(markers)) or "none"
        return [((*here, "goto"), f"no marker '{branch.goto}' (markers: {known})")]
    skills = branch_skills(branch, lib, robot_type)
    if isinstance(skills, str):
        return [(here, skills)]
    return [
        ((*here, "fallback", i, *p.path), p.message)
        for i, f in enumerate(skills)
        for p in _checked(f, lib, robot_type, markers, robots)[1]
    ]


def _checked(
    f: FallbackSkill,
    lib: Library,
    robot_type: str,
    markers: Mapping[str, Any],
    robots: set[str],
) -> tuple[dict[str, Any], list[Any]]:
    return check_params(
        lib, robot_type, f.skill, f.params, f.bindings, markers=dict(markers), robots=robots
    )


def resolved(
    s: SkillInstance,
    lib: Library,
    robot_type: str,
    markers: Mapping[str, Any],
    robots: set[str],
) -> Branches | None:
    """The skills a synchronized skill's fallback / goto branches run, with
    parameters checked and markers' values taken now (None: it has none).
    Call it on a skill whose contingencies passed `contingency_problems`."""
    lists: dict[str, list[SkillInstance]] = {}
    for trigger in TRIGGERS:
        skills = branch_skills(getattr(s.policies, trigger), lib, robot_type)
        if isinstance(skills, str) or not skills:
            continue
        lists[trigger] = [
            SkillInstance(
                id=f"{s.id[:56]}-{trigger[3]}{n}",  # lru1-4-f1: fallback 1 on failure
                skill=f.skill,
                label=f"{trigger.replace('_', ' ')} of {s.id}",
                params=_checked(f, lib, robot_type, markers, robots)[0],
                bindings=f.bindings,
                status=Status.IDLE_SYNCHRONIZED,
            )
            for n, f in enumerate(skills, 1)
        ]
    return Branches(**lists) if lists else None
