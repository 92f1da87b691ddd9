"""Skill libraries: robot types, their skills and typed parameters.

What each kind of parameter accepts is in `backend.core.params` (one table).
`check_params` is the one place where a skill's parameters are validated, for
mission files and for live operations alike, so a value refused in a file is
refused the same way from the console.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Final, Literal

from pydantic import Field

from backend.core.model import Name, Strict
from backend.core.params import ParamSpec, check_value, marker_value, normalize_value

LIBRARY_FORMAT: Final = "missionctl/library@1"
VERSION_PATTERN = r"^\d+\.\d+\.\d+$"


class DurationModel(Strict):
    """Expected duration: base + per metre travelled + per unit of parameters."""

    base_s: float = Field(10.0, ge=0)
    per_metre_s: float = Field(0.0, ge=0, description="seconds per metre to the goal parameter")
    goal_param: str | None = Field(None, description="pose/position parameter giving the goal")
    per_param_s: dict[str, float] = Field(
        default_factory=dict, description="seconds per unit of a numeric parameter"
    )


class SkillSpec(Strict):
    description: str = ""
    version: str = Field("1.0.0", pattern=VERSION_PATTERN)
    params: dict[Name, ParamSpec] = Field(default_factory=dict)
    duration: DurationModel = Field(default_factory=DurationModel)


class RobotType(Strict):
    kind: Literal["dynamic", "static"] = "dynamic"
    description: str = ""
    skills: list[Name] = Field(default_factory=list)


class Library(Strict):
    format: Literal["missionctl/library@1"] = LIBRARY_FORMAT
    name: str = "library"
    robot_types: dict[Name, RobotType] = Field(default_factory=dict)
    skills: dict[Name, SkillSpec] = Field(default_factory=dict)

    def skills_of(self, robot_type: str) -> list[str]:
        rt = self.robot_types.get(robot_type)
        return list(rt.skills) if rt else []

    def skill_for(self, robot_type: str, skill: str) -> SkillSpec | None:
        if skill not in self.skills_of(robot_type):
            return None
        return self.skills.get(skill)

    def expected_duration(
        self, skill: str, params: dict[str, Any], start: tuple[float, float] | None = None
    ) -> float:
        spec = self.skills.get(skill)
        if spec is None:
            return 0.0
        d = spec.duration
        total = d.base_s
        goal = params.get(d.goal_param) if d.goal_param else None
        if start is not None and isinstance(goal, dict):
            total += d.per_metre_s * math.hypot(
                float(goal.get("x", 0)) - start[0], float(goal.get("y", 0)) - start[1]
            )
        for name, factor in d.per_param_s.items():
            v = params.get(name)
            if isinstance(v, int | float) and not isinstance(v, bool):
                total += factor * float(v)
        return total


# -- parameter values --------------------------------------------------------


@dataclass(frozen=True)
class ParamProblem:
    path: tuple[str | int, ...]  # relative to the params mapping
    message: str


def check_params(
    library: Library,
    robot_type: str,
    skill: str,
    params: dict[str, Any],
    bindings: dict[str, str],
    *,
    markers: dict[str, Any],
    robots: set[str],
    fill_defaults: bool = True,
) -> tuple[dict[str, Any], list[ParamProblem]]:
    """Validate a skill's parameters; return (normalized params, problems).

    Bound parameters take their value from the marker. Missing optional
    parameters get their default when `fill_defaults`.
    """
    rt = library.robot_types.get(robot_type)
    if rt is None:
        return params, [ParamProblem((), f"unknown robot type '{robot_type}'")]
    spec = library.skill_for(robot_type, skill)
    if spec is None:
        offered = ", ".join(rt.skills) or "none"
        return params, [
            ParamProblem(
                (), f"robot type '{robot_type}' has no skill '{skill}' (it offers: {offered})"
            )
        ]
    problems = _unknown_names(skill, spec, params, bindings)
    out: dict[str, Any] = {}
    for name, pspec in spec.params.items():
        if name in bindings:
            problems += _take_bound(out, name, pspec, bindings[name], markers)
        elif name not in params or params[name] is None:
            problems += _take_default(out, name, pspec, fill_defaults)
        else:
            problems += _take_given(out, name, pspec, params[name], markers, robots)
    return out, problems


def _unknown_names(
    skill: str, spec: SkillSpec, params: dict[str, Any], bindings: dict[str, str]
) -> list[ParamProblem]:
    problems: list[ParamProblem] = []
    for name in params:
        if name not in spec.params:
            known = ", ".join(spec.params) or "none"
            problems.append(
                ParamProblem(
                    (name,), f"skill '{skill}' has no parameter '{name}' (parameters: {known})"
                )
            )
    for name in bindings:
        if name not in spec.params:
            problems.append(
                ParamProblem((name,), f"cannot bind unknown parameter '{name}' of skill '{skill}'")
            )
    return problems


# Each of the three ways a parameter gets its value (bound to a marker, left
# out, given) puts the value in `out` when there is one, and says what is wrong.


def _take_bound(
    out: dict[str, Any], name: str, pspec: ParamSpec, mname: str, markers: dict[str, Any]
) -> list[ParamProblem]:
    marker = markers.get(mname)
    if marker is None:
        known = ", ".join(sorted(markers)) or "none"
        return [ParamProblem((name,), f"unknown marker '{mname}' (markers: {known})")]
    value, why = marker_value(pspec, marker)
    if why:
        return [ParamProblem((name,), f"cannot bind to marker '{mname}': {why}")]
    out[name] = value
    return []


def _take_default(
    out: dict[str, Any], name: str, pspec: ParamSpec, fill_defaults: bool
) -> list[ParamProblem]:
    if pspec.default is not None and fill_defaults:
        out[name] = normalize_value(pspec, pspec.default)
    elif pspec.is_required:
        unit = f" in {pspec.unit}" if pspec.unit else ""
        return [ParamProblem((name,), f"missing required {pspec.type} parameter '{name}'{unit}")]
    return []


def _take_given(
    out: dict[str, Any],
    name: str,
    pspec: ParamSpec,
    value: Any,
    markers: dict[str, Any],
    robots: set[str],
) -> list[ParamProblem]:
    found = check_value(pspec, value, markers=markers, robots=robots)
    if found:
        return [ParamProblem((name, *rel), msg) for rel, msg in found]
    out[name] = normalize_value(pspec, value)
    return []
