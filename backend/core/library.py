"""Skill libraries: robot types, their skills and typed parameters.

What each kind of parameter accepts is in `backend.core.params` (one table).
`check_params` is the one place where a skill's parameters are validated, for
mission files and for live operations alike, so a value refused in a file is
refused the same way from the console.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Final, Literal

from pydantic import Field

from backend.core.model import Name, ParamType, Strict
from backend.core.params import ParamSpec, check_value, marker_value, normalize_value

LIBRARY_FORMAT: Final = "missionctl/library@1"
PropertyValue = str | int | float | bool
VERSION_PATTERN = r"^\d+\.\d+\.\d+$"


class DurationModel(Strict):
    """Expected duration of a skill, in robot seconds: base + travel + per
    unit of parameters + charging. Travel is to the goal parameter (or home):
    route length / speed when a speed is known (the speed parameter, else the
    robot type's `speed_mps`), else `per_metre_s` per metre."""

    base_s: float = Field(10.0, ge=0)
    per_metre_s: float = Field(
        0.0, ge=0, description="seconds per metre to the goal, when no speed is known"
    )
    goal_param: str | None = Field(None, description="pose/position parameter giving the goal")
    speed_param: str | None = Field(
        None, description="numeric parameter giving the travel speed, m/s"
    )
    to_home: bool | dict[Name, str | float | bool] = Field(
        False,
        description="the skill first travels home (the recharge station): always (true), or "
        "when each named parameter has the given value (e.g. {where: lander_pad})",
    )
    charge_param: str | None = Field(
        None,
        description="numeric parameter giving the battery level (0..1) the skill charges to; "
        "charging takes (level - battery) / the robot type's battery.charge_per_s",
    )
    area_param: str | None = Field(
        None,
        description="area parameter the skill works in: the robot is predicted to end at its "
        "centre, its comms coverage is checked over it, and a robot type with a survey rate "
        "is done once it has mapped it (if that is sooner)",
    )
    per_param_s: dict[str, float] = Field(
        default_factory=dict, description="seconds per unit of a numeric parameter"
    )

    def goes_home(self, params: dict[str, Any]) -> bool:
        if isinstance(self.to_home, bool):
            return self.to_home
        return all(params.get(k) == v for k, v in self.to_home.items())


class EnergyRates(Strict):
    """Battery use as fractions of a full battery; unset: the robot type's."""

    per_s: float | None = Field(None, ge=0, le=1, description="per second of the skill")
    per_metre: float | None = Field(None, ge=0, le=1, description="per metre travelled")


class EnergyModel(EnergyRates):
    """A skill's battery use; `by_type` replaces the rates for some robot types
    (a drone exploring flies, a rover drives)."""

    by_type: dict[Name, EnergyRates] = Field(default_factory=dict)

    def rates(self, robot_type: str, battery: BatteryModel) -> tuple[float, float]:
        """(per second, per metre) for a robot of this type."""
        mine = self.by_type.get(robot_type, _NO_RATES)
        return (
            _first_set(mine.per_s, self.per_s, battery.per_s),
            _first_set(mine.per_metre, self.per_metre, battery.per_metre),
        )


_NO_RATES = EnergyRates()  # a robot type without rates of its own


def _first_set(for_type: float | None, for_skill: float | None, battery: float) -> float:
    """The rate the robot type's entry sets, else the skill's, else the battery's."""
    if for_type is not None:
        return for_type
    return for_skill if for_skill is not None else battery


class BatteryModel(Strict):
    """A robot type's battery, as fractions of a full one (plan checks and
    predictions; the robot itself decides what it does)."""

    reserve: float = Field(
        0.05, ge=0, lt=1, description="the level the robot stops at: 'empty' means down to this"
    )
    margin: float = Field(
        0.2, ge=0, le=1, description="plan checks warn when the battery is predicted below this"
    )
    per_s: float = Field(0.0, ge=0, le=1, description="use per second of any skill")
    per_metre: float = Field(0.0, ge=0, le=1, description="use per metre travelled")
    charge_per_s: float = Field(0.0, ge=0, le=1, description="charging rate at home, per second")


class SkillSignature(Strict):
    """A skill as a robot needs to know it to check its handler (sent in each
    accepted registration): each parameter's kind, the required ones, and
    the value the server gives one left out (the library's default)."""

    params: dict[Name, ParamType] = Field(default_factory=dict, description="parameter -> its kind")
    required: list[Name] = Field(
        default_factory=list, description="parameters that always have a value"
    )
    defaults: dict[Name, Any] = Field(
        default_factory=dict,
        description="parameter -> the value the server fills in when it is left out (the "
        "library's default, normalized); a robot running the skill on its own (a recharge "
        "before a skill) calls it with these",
    )


class SkillSpec(Strict):
    description: str = ""
    version: str = Field("1.0.0", pattern=VERSION_PATTERN)
    params: dict[Name, ParamSpec] = Field(default_factory=dict)
    duration: DurationModel = Field(default_factory=DurationModel)
    energy: EnergyModel = Field(default_factory=EnergyModel)
    needs_comms: bool = Field(
        False,
        description="the skill needs the operator's link while it runs (plan checks flag it "
        "when it is planned out of comms coverage)",
    )
    talks_to: Name | None = Field(
        None,
        description="robot parameter naming a robot the skill talks to while it runs (e.g. a "
        "partner it works with): both must be able to talk, through comms coverage or within "
        "their radio range (plan checks flag it when it is planned out of coverage)",
    )

    def kinds(self) -> dict[str, ParamType]:
        """Parameter -> its kind: what travels with the values to the robot."""
        return {name: p.type for name, p in self.params.items()}

    def signature(self) -> SkillSignature:
        return SkillSignature(
            params=self.kinds(),
            required=[name for name, p in self.params.items() if p.is_required],
            defaults={
                name: default_value(p) for name, p in self.params.items() if p.default is not None
            },
        )


class RobotType(Strict):
    kind: Literal["dynamic", "static"] = "dynamic"
    description: str = ""
    skills: list[Name] = Field(default_factory=list)
    speed_mps: float | None = Field(
        None, gt=0, le=1000, description="cruise speed, m/s, for travel without a speed parameter"
    )
    flies: bool = Field(
        False, description="it flies: straight lines, and the ground's terrain does not matter"
    )
    survey_m2_per_s: float | None = Field(
        None,
        gt=0,
        le=1e6,
        description="area it maps per second (its sensor's swath times its speed), for skills "
        "working in an area",
    )
    battery: BatteryModel | None = Field(
        None, description="battery model for predictions and plan checks; none: no battery"
    )
    radio_range_m: float = Field(
        0.0,
        ge=0,
        le=1e6,
        description="robots this close talk to each other without comms coverage (a direct "
        "radio); 0: only through the comms network, so partners at a barrier meet only where "
        "both are covered",
    )
    properties: dict[Name, PropertyValue] = Field(
        default_factory=dict,
        description="the figures an operator plans with (ranges, capacities; units in the "
        "names: _m, _s, _mps), as the manifests of robots of this type declare them",
    )


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
    spec = _offered(library, robot_type, skill)
    if isinstance(spec, ParamProblem):
        return params, [spec]
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


def _offered(library: Library, robot_type: str, skill: str) -> SkillSpec | ParamProblem:
    """The skill's spec, or why the robot type does not offer it."""
    rt = library.robot_types.get(robot_type)
    if rt is None:
        return ParamProblem((), f"unknown robot type '{robot_type}'")
    spec = library.skill_for(robot_type, skill)
    if spec is None:
        offered = ", ".join(rt.skills) or "none"
        return ParamProblem(
            (), f"robot type '{robot_type}' has no skill '{skill}' (it offers: {offered})"
        )
    return spec


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


def default_value(pspec: ParamSpec) -> Any:
    """The value a parameter left out gets (the one fill-in of defaults)."""
    return normalize_value(pspec, pspec.default) if pspec.default is not None else None


def _take_default(
    out: dict[str, Any], name: str, pspec: ParamSpec, fill_defaults: bool
) -> list[ParamProblem]:
    if pspec.default is not None and fill_defaults:
        out[name] = default_value(pspec)
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
