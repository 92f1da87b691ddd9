"""Contingencies (policies on_failure / on_timeout) against a library and a
mission's markers: what a file or an operation may ask for, and the concrete
skills the robot gets with the sync for a fallback or a goto.

A fallback's skills must be skills of the robot's type with valid parameters;
a goto's marker must exist and the robot's type must have a drive skill: its
first skill that only travels (a duration model with a goal and a speed
parameter and no base time: drive_to, fly_to).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from datetime import UTC, datetime
from typing import Any, Literal

from pydantic import TypeAdapter, ValidationError

from backend.core.contact import sim_time_text
from backend.core.durations import duration_s, instant_s
from backend.core.library import Library, SkillSpec, check_params
from backend.core.model import (
    FINISHED,
    Branch,
    Branches,
    Fallback,
    FallbackSkill,
    Goto,
    Mission,
    Policies,
    SkillInstance,
    Status,
    Taken,
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


def after_problems(m: Mission, robot: str, policies: Policies) -> list[Problem]:
    """policies.after names a skill of another robot of the mission."""
    if policies.after is None:
        return []
    found = m.find(policies.after)
    if found is None or found[0] == robot:
        why = "no such skill" if found is None else f"it is {robot}'s own (order it in the plan)"
        return [(("policies", "after"), f"after {policies.after}: {why}")]
    return []


def awaited_outcomes(m: Mission, robot: str) -> dict[str, Literal["success", "failure"]]:
    """How `robot`'s finished skills ended that an unfinished skill of another
    robot waits for (policies.after): what a restarted robot must still answer."""
    out: dict[str, Literal["success", "failure"]] = {}
    for other, task in m.tasks.items():
        for s in task:
            found = _awaited(m, other, s)
            if found is not None and found[0] == robot:
                out[found[2].id] = "success" if found[2].status == Status.SUCCESS else "failure"
    return out


def _awaited(m: Mission, robot: str, s: SkillInstance) -> tuple[str, int, SkillInstance] | None:
    """The finished skill of another robot that unfinished `s` waits for."""
    if s.policies.after is None or s.status in FINISHED:
        return None
    found = m.find(s.policies.after)
    if found is None or found[0] == robot or found[2].status not in FINISHED:
        return None
    return found


def _branch_problems(
    branch: Branch,
    trigger: str,
    lib: Library,
    robot_type: str,
    markers: Mapping[str, Any],
    robots: set[str],
) -> list[Problem]:
    here: Path = ("policies", trigger)
    skills = branch_skills(branch, lib, robot_type)
    if isinstance(skills, str):
        return [(here, skills)]
    # a goto is its drive skill bound to the marker: an unknown marker is its problem
    kind = "goto" if isinstance(branch, Goto) else "fallback"
    return [
        ((*here, kind, i, *p.path), p.message)
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


# -- how rows show them ---------------------------------------------------------


def span_text(seconds: float) -> str:
    """600 -> '10m', 5400 -> '90m', 7200 -> '2h', 45 -> '45s'."""
    for unit, size in (("h", 3600), ("m", 60)):
        if seconds >= size and seconds % size == 0:
            return f"{seconds / size:g}{unit}"
    return f"{seconds:g}s"


def clock_text(t: float) -> str:
    """A mission-clock instant: sim time, or a UTC time on a POSIX clock."""
    if t >= POSIX_FROM:
        return datetime.fromtimestamp(t, UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    return f"sim {sim_time_text(t)}"


POSIX_FROM = 1e9  # no simulated mission runs 31 years: beyond it, the clock is POSIX


def branch_text(branch: Branch) -> str:
    """'skip', 'recharge@Lander' (a fallback, with its skills' markers), 'goto@Lander'."""
    if isinstance(branch, Goto):
        return f"goto@{branch.goto}"
    if isinstance(branch, Fallback):
        return "+".join(
            f.skill + "".join(f"@{m}" for m in f.bindings.values()) for f in branch.fallback
        )
    return branch


# the marks' symbols: then, failed, timeout, no later than; in unicode and in ASCII
_SYMBOLS = {True: ("→", "✗", "⏱", "≤"), False: ("->", "X", "T", "<=")}


def marks(p: Policies, unicode: bool = True) -> list[str]:
    """A row's contingency marks: '⏱10m→skip', '✗→recharge@Lander' (ASCII: T10m->skip)."""
    arrow, failed, _, _ = _SYMBOLS[unicode]
    out = [_timeout_mark(p, unicode) + arrow + branch_text(p.on_timeout)]
    out = out if p.timeout is not None or p.not_after is not None else []
    if p.after is not None:
        out.append(f"after {p.after}")
    if p.on_failure != "halt":
        out.append(failed + arrow + branch_text(p.on_failure))
    return out


def _timeout_mark(p: Policies, unicode: bool) -> str:
    """'⏱10m', '⏱≤sim 2:00:00', '⏱10m,≤sim 2:00:00' (ASCII: T10m, T<=sim 2:00:00)."""
    _, _, timeout, by = _SYMBOLS[unicode]
    limits = [span_text(p.timeout)] if p.timeout is not None else []
    if p.not_after is not None:  # an instant of the mission clock, said as one
        limits.append(by + clock_text(p.not_after))
    return timeout + ",".join(limits)


def awaited_by(m: Mission) -> dict[str, list[str]]:
    """Skill id -> the skills that start only after it (their policies.after)."""
    out: dict[str, list[str]] = {}
    for task in m.tasks.values():
        for s in task:
            if s.policies.after is not None:
                out.setdefault(s.policies.after, []).append(s.id)
    return out


def after_tags(p: Policies, waiting: list[str], unicode: bool = True) -> list[str]:
    """The tags of both rows of an `after`, like a barrier's: '⇠lander-1' (it
    starts after lander-1), '⇢lru2-4' (lru2-4 starts after it; '+1' more).
    ASCII: 'after:lander-1', 'before:lru2-4'."""
    out = [("⇠" if unicode else "after:") + p.after] if p.after is not None else []
    if waiting:
        more = f"+{len(waiting) - 1}" if len(waiting) > 1 else ""
        out.append(("⇢" if unicode else "before:") + waiting[0] + more)
    return out


def taken_text(t: Taken) -> str:
    """What a robot did: 'on failure: skip', 'on timeout: fallback'."""
    return f"on {t.trigger}: {t.branch}"


# -- as people type them (ctl options, the console's editor) ------------------------

OFF = ("", "off", "none", "no", "never")
BRANCH_SYNTAX = "halt | skip | continue | goto:MARKER | fallback:SKILL[+SKILL...]"


def read_seconds(text: str) -> float | None | str:
    """'10m', '1.5h', '90' -> seconds; 'off' or empty -> None; else what is wrong."""
    if text.strip().lower() in OFF:
        return None
    seconds = duration_s(text)
    if seconds is None:
        return f"expected a mission-time duration such as 90s, 10m, 1.5h (or 'off'), got {text!r}"
    return seconds


INSTANT_SYNTAX = (
    "a mission-clock time: sim 2:00:00 (or 2:00:00, or 2h: two hours of sim time), "
    "or a UTC time 2030-07-01 14:32 on a real mission"
)


def read_instant(text: str) -> float | None | str:
    """policies.not_after as people type it (backend.core.durations.instant_s);
    'off' or empty -> None; else what is wrong."""
    if text.strip().lower() in OFF:
        return None
    at = instant_s(text)
    return at if at is not None else f"expected {INSTANT_SYNTAX} (or 'off'), got {text!r}"


def read_branch(text: str) -> Branch | None:
    """A branch from 'skip', 'goto:Lander', 'fallback:recharge+explore'; None
    when it is none of them (see BRANCH_SYNTAX). The model checks the words
    and the names."""
    word, colon, rest = text.strip().partition(":")
    shape = _SHAPES.get(word) if colon else (lambda _rest: word)
    try:
        return _BRANCH.validate_python(shape(rest)) if shape is not None else None
    except ValidationError:
        return None


# what 'goto:X' and 'fallback:A+B' stand for, as the model reads them
_SHAPES: dict[str, Callable[[str], Any]] = {
    "goto": lambda rest: {"goto": rest},
    "fallback": lambda rest: {"fallback": [{"skill": n} for n in rest.split("+")]},
}
_BRANCH: TypeAdapter[Branch] = TypeAdapter(Branch)


def typed_branch(branch: Branch) -> str:
    """The text `read_branch` reads back (a fallback's parameters are not in it)."""
    if isinstance(branch, Goto):
        return f"goto:{branch.goto}"
    if isinstance(branch, Fallback):
        return "fallback:" + "+".join(f.skill for f in branch.fallback)
    return branch
