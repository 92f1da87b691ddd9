"""Contingencies in live operations: a skill's fallback / goto checked where
it is set (add, edit), made concrete where it is sent (sync, retry)."""

from __future__ import annotations

from collections.abc import Sequence

from backend.core.contingency import after_problems, contingency_problems, resolved
from backend.core.model import Branches, ParamType, Policies, SkillInstance, format_path
from backend.core.rules.base import Refusal, Rules


def check(rules: Rules, robot: str, policies: Policies | None, skill_id: str | None) -> None:
    """Refused, naming every problem, unless the contingencies can run on `robot`."""
    if policies is None:
        return
    m = rules.mission
    problems = contingency_problems(
        policies, rules.library, rules.robot_type(robot), m.markers, set(m.robots)
    ) + after_problems(m, robot, policies)
    if problems:
        who = f"{skill_id}: " if skill_id else ""
        text = "; ".join(f"{format_path(path)}: {why}" for path, why in problems)
        raise Refusal(
            "bad_contingency",
            f"{who}{text} (fallback skills must be skills of {robot} with valid parameters; "
            "a goto needs a marker)",
            robot=robot,
            skill=skill_id,
        )


def branches(rules: Rules, robot: str, skills: Sequence[SkillInstance]) -> dict[str, Branches]:
    """Skill id -> the skills its fallback / goto branches run, for an Enqueue."""
    m = rules.mission
    rtype = rules.robot_type(robot)
    out: dict[str, Branches] = {}
    for s in skills:
        check(rules, robot, s.policies, s.id)  # a marker may have gone since it was set
        b = resolved(s, rules.library, rtype, m.markers, set(m.robots))
        if b is not None:
            out[s.id] = b
    return out


def run_by(found: dict[str, Branches]) -> list[SkillInstance]:
    """Every skill the branches run."""
    return [s for b in found.values() for s in (*b.on_failure, *b.on_timeout)]


def kinds(rules: Rules, found: dict[str, Branches]) -> dict[str, dict[str, ParamType]]:
    """The parameter kinds of the skills the branches run (Enqueue.kinds)."""
    lib = rules.library.skills
    return {s.skill: lib[s.skill].kinds() for s in run_by(found) if s.skill in lib}


def afters(rules: Rules, skills: Sequence[SkillInstance]) -> dict[str, str]:
    """Skill id -> the robot running the skill it waits for (Enqueue.after)."""
    out: dict[str, str] = {}
    for s in skills:
        found = rules.mission.find(s.policies.after) if s.policies.after else None
        if found is not None:
            out[s.id] = found[0]
    return out
