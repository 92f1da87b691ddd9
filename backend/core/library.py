"""Skill libraries: robot types, their skills and typed parameters.

`check_params` is the one place where parameter values are validated, for
mission files and for live operations alike, so a value refused in a file is
refused the same way from the console.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

from pydantic import Field, model_validator

from backend.core.model import (
    AreaMarker,
    Name,
    Pose,
    PoseMarker,
    Position,
    PositionMarker,
    Strict,
)

LIBRARY_FORMAT = "missionctl/library@1"
VERSION_PATTERN = r"^\d+\.\d+\.\d+$"

ParamType = Literal[
    "bool",
    "int",
    "float",
    "str",
    "list",
    "dict",
    "pose",
    "position",
    "area",
    "enum",
    "marker",
    "robot",
]

POSE_FIELDS = ("x", "y", "z", "roll", "pitch", "yaw")
POSITION_FIELDS = ("x", "y", "z")


class ParamSpec(Strict):
    type: ParamType
    description: str = ""
    default: Any = None
    required: bool | None = Field(
        None,
        description="a value must be given; unset means: required when there is no default",
    )
    unit: str = ""
    min: float | None = None
    max: float | None = None
    choices: list[str] | None = Field(None, description="allowed values of an enum")
    marker_kinds: list[Literal["pose", "position", "area"]] | None = Field(
        None, description="marker parameters: which kinds of marker may be chosen"
    )

    @model_validator(mode="after")
    def _coherent(self) -> ParamSpec:
        if self.type == "enum" and not self.choices:
            raise ValueError("an enum parameter needs a non-empty 'choices' list")
        if self.type != "enum" and self.choices is not None:
            raise ValueError("'choices' only applies to enum parameters")
        if (self.min is not None or self.max is not None) and self.type not in ("int", "float"):
            raise ValueError("'min'/'max' only apply to int and float parameters")
        if self.min is not None and self.max is not None and self.min > self.max:
            raise ValueError(f"min {self.min} is greater than max {self.max}")
        return self

    def default_problem(self) -> str | None:
        """Why the default does not fit the spec (checked with the library file,
        so the error points at the default itself)."""
        if self.default is None:
            return None
        problems = check_value(self, self.default, markers=None, robots=None)
        return problems[0][1] if problems else None

    @property
    def is_required(self) -> bool:
        return self.required if self.required is not None else self.default is None


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


def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _check_fields(v: Any, fields: tuple[str, ...], what: str) -> list[tuple[tuple, str]]:
    if not isinstance(v, dict):
        return [((), f"expected a {what} mapping with {', '.join(fields)}, got {_kind(v)}")]
    out: list[tuple[tuple, str]] = []
    for k in v:
        if k not in fields:
            out.append(((k,), f"unknown {what} field '{k}' (fields: {', '.join(fields)})"))
    for f in fields:
        if f in v and not _number(v[f]):
            out.append(((f,), f"expected a number, got {_kind(v[f])}"))
        elif f in v and not math.isfinite(float(v[f])):
            out.append(((f,), "expected a finite number"))
    return out


def _kind(v: Any) -> str:
    if v is None:
        return "nothing (null)"
    if isinstance(v, bool):
        return f"a boolean ({v})"
    if isinstance(v, int):
        return f"an integer ({v})"
    if isinstance(v, float):
        return f"a number ({v})"
    if isinstance(v, str):
        return f"a string ({v!r})"
    if isinstance(v, list):
        return "a list"
    if isinstance(v, dict):
        return "a mapping"
    return type(v).__name__


def check_value(
    spec: ParamSpec, v: Any, *, markers: dict[str, Any] | None, robots: set[str] | None
) -> list[tuple[tuple, str]]:
    """Problems of one value against its spec: [(relative path, sentence)].

    `markers`/`robots` None: references are not checked (library defaults).
    """
    t = spec.type
    if t == "bool":
        return [] if isinstance(v, bool) else [((), f"expected true or false, got {_kind(v)}")]
    if t in ("int", "float"):
        if t == "int" and not (isinstance(v, int) and not isinstance(v, bool)):
            return [((), f"expected an integer, got {_kind(v)}")]
        if t == "float" and not _number(v):
            return [((), f"expected a number, got {_kind(v)}")]
        if not math.isfinite(float(v)):
            return [((), "expected a finite number")]
        unit = f" {spec.unit}" if spec.unit else ""
        if spec.min is not None and v < spec.min:
            return [((), f"{v}{unit} is below the minimum {spec.min:g}{unit}")]
        if spec.max is not None and v > spec.max:
            return [((), f"{v}{unit} is above the maximum {spec.max:g}{unit}")]
        return []
    if t == "str":
        return [] if isinstance(v, str) else [((), f"expected a string, got {_kind(v)}")]
    if t == "list":
        return [] if isinstance(v, list) else [((), f"expected a list, got {_kind(v)}")]
    if t == "dict":
        return [] if isinstance(v, dict) else [((), f"expected a mapping, got {_kind(v)}")]
    if t == "pose":
        return _check_fields(v, POSE_FIELDS, "pose")
    if t == "position":
        return _check_fields(v, POSITION_FIELDS, "position")
    if t == "area":
        if not isinstance(v, list) or len(v) < 3:
            return [((), f"expected a polygon: a list of at least 3 positions, got {_kind(v)}")]
        out: list[tuple[tuple, str]] = []
        for i, p in enumerate(v):
            out += [((i, *rel), msg) for rel, msg in _check_fields(p, POSITION_FIELDS, "position")]
        return out
    if t == "enum":
        choices = spec.choices or []
        if v not in choices:
            return [((), f"{v!r} is not one of: {', '.join(choices)}")]
        return []
    if t == "marker":
        if not isinstance(v, str):
            return [((), f"expected a marker name, got {_kind(v)}")]
        if markers is not None and v not in markers:
            return [((), f"unknown marker '{v}' (markers: {', '.join(sorted(markers)) or 'none'})")]
        m = markers.get(v) if markers is not None else None
        if m is not None and spec.marker_kinds and m.kind not in spec.marker_kinds:
            return [
                ((), f"marker '{v}' is a {m.kind} marker; expected {'/'.join(spec.marker_kinds)}")
            ]
        return []
    if t == "robot":
        if not isinstance(v, str):
            return [((), f"expected a robot name, got {_kind(v)}")]
        if robots is not None and v not in robots:
            return [((), f"unknown robot '{v}' (robots: {', '.join(sorted(robots))})")]
        return []
    return [((), f"unknown parameter type {t}")]


def normalize_value(spec: ParamSpec, v: Any) -> Any:
    """Canonical form of a valid value: full poses/positions, floats as floats."""
    if spec.type == "pose":
        return Pose(**v).model_dump()
    if spec.type == "position":
        return Position(**v).model_dump()
    if spec.type == "area":
        return [Position(**p).model_dump() for p in v]
    if spec.type == "float":
        return float(v)
    return v


def marker_value(spec: ParamSpec, marker: Any) -> tuple[Any, str | None]:
    """Value a marker gives to a bound parameter, or (None, reason it cannot)."""
    if spec.type == "pose":
        if isinstance(marker, PoseMarker):
            return marker.pose.model_dump(), None
        if isinstance(marker, PositionMarker):
            return Pose(**marker.position.model_dump()).model_dump(), None
        return None, "an area marker cannot give a pose"
    if spec.type == "position":
        if isinstance(marker, PoseMarker):
            p = marker.pose
            return Position(x=p.x, y=p.y, z=p.z).model_dump(), None
        if isinstance(marker, PositionMarker):
            return marker.position.model_dump(), None
        return None, "an area marker cannot give a position"
    if spec.type == "area":
        if isinstance(marker, AreaMarker):
            return [p.model_dump() for p in marker.area], None
        return None, f"a {marker.kind} marker cannot give an area"
    return None, f"a {spec.type} parameter cannot be bound to a marker"


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
    problems: list[ParamProblem] = []
    out: dict[str, Any] = {}
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
    for name, pspec in spec.params.items():
        if name in bindings:
            mname = bindings[name]
            marker = markers.get(mname)
            if marker is None:
                known = ", ".join(sorted(markers)) or "none"
                problems.append(
                    ParamProblem((name,), f"unknown marker '{mname}' (markers: {known})")
                )
                continue
            value, why = marker_value(pspec, marker)
            if why:
                problems.append(ParamProblem((name,), f"cannot bind to marker '{mname}': {why}"))
                continue
            out[name] = value
            continue
        if name not in params or params[name] is None:
            if pspec.default is not None and fill_defaults:
                out[name] = normalize_value(pspec, pspec.default)
            elif pspec.is_required:
                unit = f" in {pspec.unit}" if pspec.unit else ""
                problems.append(
                    ParamProblem((name,), f"missing required {pspec.type} parameter '{name}'{unit}")
                )
            continue
        found = check_value(pspec, params[name], markers=markers, robots=robots)
        if found:
            problems += [ParamProblem((name, *rel), msg) for rel, msg in found]
        else:
            out[name] = normalize_value(pspec, params[name])
    return out, problems
