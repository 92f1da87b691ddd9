"""The one registry of parameter kinds: what each kind of skill parameter accepts,
its canonical form, what a marker gives it, a starting value for a new skill,
and the typed value a skill handler receives.

Libraries, mission files, the rules, `ctl`, the robot agent and the console all
ask this table (`KINDS[spec.type]`) instead of switching on the kind each on
its own, so a kind behaves the same everywhere.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

from pydantic import Field, model_validator

from backend.core.limits import echo, value_problem
from backend.core.model import AreaMarker, Pose, PoseMarker, Position, PositionMarker, Strict

POSE_FIELDS = ("x", "y", "z", "roll", "pitch", "yaw")
POSITION_FIELDS = ("x", "y", "z")

Problem = tuple[tuple[str | int, ...], str]  # (path relative to the value, sentence)
Markers = Mapping[str, Any]  # marker name -> PoseMarker | PositionMarker | AreaMarker


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

    @property
    def kind(self) -> Kind:
        """What this parameter's kind accepts and how it behaves (`KINDS`)."""
        return KINDS[self.type]


def describe(v: Any) -> str:
    """What a value is, for an error sentence ('a string ('x')')."""
    if v is None:
        return "nothing (null)"
    if isinstance(v, bool):
        return f"a boolean ({v})"
    if isinstance(v, int):
        return f"an integer ({v})"
    if isinstance(v, float):
        return f"a number ({v})"
    if isinstance(v, str):
        return f"a string ({echo(v)})"
    if isinstance(v, list):
        return "a list"
    if isinstance(v, dict):
        return "a mapping"
    return type(v).__name__


def is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _check_fields(v: Any, fields: tuple[str, ...], what: str) -> list[Problem]:
    if not isinstance(v, dict):
        return [((), f"expected a {what} mapping with {', '.join(fields)}, got {describe(v)}")]
    out: list[Problem] = []
    for k in v:
        if k not in fields:
            out.append(((k,), f"unknown {what} field '{k}' (fields: {', '.join(fields)})"))
    for f in fields:
        if f in v and not is_number(v[f]):
            out.append(((f,), f"expected a number, got {describe(v[f])}"))
        elif f in v and not math.isfinite(float(v[f])):
            out.append(((f,), "expected a finite number"))
    return out


@dataclass(frozen=True)
class StartContext:
    """What a starting value may draw on: where the robot is, the mission's
    markers and robots, and which robot the skill is for."""

    robot: str
    pose: dict[str, float] = field(default_factory=lambda: dict.fromkeys(POSE_FIELDS, 0.0))
    markers: Markers = field(default_factory=dict)
    robots: tuple[str, ...] = ()


class Kind:
    """One kind of parameter. Subclasses override what differs."""

    name: ClassVar[str]
    # marker kinds a parameter of this kind can be bound to (its value follows the marker)
    bindable_to: ClassVar[tuple[str, ...]] = ()
    names_marker: ClassVar[bool] = False  # the value is a marker's name
    numeric: ClassVar[bool] = False  # a number (a duration may grow with it)
    goal: ClassVar[bool] = False  # a place to go to (a duration may grow with the distance)

    def check(
        self, spec: ParamSpec, v: Any, markers: Markers | None, robots: Collection[str] | None
    ) -> list[Problem]:
        raise NotImplementedError

    def normalize(self, spec: ParamSpec, v: Any) -> Any:
        """Canonical form of a valid value."""
        return v

    def from_marker(self, spec: ParamSpec, marker: Any) -> tuple[Any, str | None]:
        """Value a marker gives to a bound parameter, or (None, why it cannot)."""
        return None, f"a {self.name} parameter cannot be bound to a marker"

    def start(self, spec: ParamSpec, ctx: StartContext) -> tuple[Any, str | None]:
        """(value, marker to bind) for a required parameter with no default,
        so a new skill is valid at once; (None, None): nothing sensible."""
        return None, None

    def typed(self, v: Any) -> Any:
        """The value as a skill handler receives it."""
        return v


class _Simple(Kind):
    """A kind checked by its Python type alone."""

    types: ClassVar[tuple[type, ...]]
    expected: ClassVar[str]
    empty: ClassVar[Any]

    def check(
        self, spec: ParamSpec, v: Any, markers: Markers | None, robots: Collection[str] | None
    ) -> list[Problem]:
        if isinstance(v, self.types):
            return []
        return [((), f"expected {self.expected}, got {describe(v)}")]

    def start(self, spec: ParamSpec, ctx: StartContext) -> tuple[Any, str | None]:
        return (self.empty() if callable(self.empty) else self.empty), None


class Bool(_Simple):
    name, types, expected, empty = "bool", (bool,), "true or false", False


class Str(_Simple):
    name, types, expected, empty = "str", (str,), "a string", ""


class List(_Simple):
    name, types, expected, empty = "list", (list,), "a list", list


class Dict(_Simple):
    name, types, expected, empty = "dict", (dict,), "a mapping", dict


class _Number(Kind):
    integer: ClassVar[bool]
    numeric = True

    def check(
        self, spec: ParamSpec, v: Any, markers: Markers | None, robots: Collection[str] | None
    ) -> list[Problem]:
        if self.integer and not (isinstance(v, int) and not isinstance(v, bool)):
            return [((), f"expected an integer, got {describe(v)}")]
        if not self.integer and not is_number(v):
            return [((), f"expected a number, got {describe(v)}")]
        if not math.isfinite(float(v)):
            return [((), "expected a finite number")]
        unit = f" {spec.unit}" if spec.unit else ""
        if spec.min is not None and v < spec.min:
            return [((), f"{v}{unit} is below the minimum {spec.min:g}{unit}")]
        if spec.max is not None and v > spec.max:
            return [((), f"{v}{unit} is above the maximum {spec.max:g}{unit}")]
        return []

    def start(self, spec: ParamSpec, ctx: StartContext) -> tuple[Any, str | None]:
        v = spec.min if spec.min is not None else 0
        if spec.max is not None:
            v = min(v, spec.max)
        return (int(v) if self.integer else float(v)), None


class Int(_Number):
    name, integer = "int", True


class Float(_Number):
    name, integer = "float", False

    def normalize(self, spec: ParamSpec, v: Any) -> Any:
        return float(v)


class PoseKind(Kind):
    name = "pose"
    bindable_to = ("pose", "position")
    goal = True

    def check(
        self, spec: ParamSpec, v: Any, markers: Markers | None, robots: Collection[str] | None
    ) -> list[Problem]:
        return _check_fields(v, POSE_FIELDS, "pose")

    def normalize(self, spec: ParamSpec, v: Any) -> Any:
        return Pose(**v).model_dump()

    def from_marker(self, spec: ParamSpec, marker: Any) -> tuple[Any, str | None]:
        if isinstance(marker, PoseMarker):
            return marker.pose.model_dump(), None
        if isinstance(marker, PositionMarker):
            return Pose(**marker.position.model_dump()).model_dump(), None
        return None, "an area marker cannot give a pose"

    def start(self, spec: ParamSpec, ctx: StartContext) -> tuple[Any, str | None]:
        return dict(ctx.pose), None

    def typed(self, v: Any) -> Any:
        return Pose(**v)


class PositionKind(Kind):
    name = "position"
    bindable_to = ("pose", "position")
    goal = True

    def check(
        self, spec: ParamSpec, v: Any, markers: Markers | None, robots: Collection[str] | None
    ) -> list[Problem]:
        return _check_fields(v, POSITION_FIELDS, "position")

    def normalize(self, spec: ParamSpec, v: Any) -> Any:
        return Position(**v).model_dump()

    def from_marker(self, spec: ParamSpec, marker: Any) -> tuple[Any, str | None]:
        if isinstance(marker, PoseMarker):
            p = marker.pose
            return Position(x=p.x, y=p.y, z=p.z).model_dump(), None
        if isinstance(marker, PositionMarker):
            return marker.position.model_dump(), None
        return None, "an area marker cannot give a position"

    def start(self, spec: ParamSpec, ctx: StartContext) -> tuple[Any, str | None]:
        return {k: ctx.pose[k] for k in POSITION_FIELDS}, None

    def typed(self, v: Any) -> Any:
        return Position(**v)


class AreaKind(Kind):
    name = "area"
    bindable_to = ("area",)
    START_HALF_SIDE = 5.0  # metres: the square a new area starts as, around the robot

    def check(
        self, spec: ParamSpec, v: Any, markers: Markers | None, robots: Collection[str] | None
    ) -> list[Problem]:
        if not isinstance(v, list) or len(v) < 3:
            return [((), f"expected a polygon: a list of at least 3 positions, got {describe(v)}")]
        out: list[Problem] = []
        for i, p in enumerate(v):
            out += [((i, *rel), msg) for rel, msg in _check_fields(p, POSITION_FIELDS, "position")]
        return out

    def normalize(self, spec: ParamSpec, v: Any) -> Any:
        return [Position(**p).model_dump() for p in v]

    def from_marker(self, spec: ParamSpec, marker: Any) -> tuple[Any, str | None]:
        if isinstance(marker, AreaMarker):
            return [p.model_dump() for p in marker.area], None
        return None, f"a {marker.kind} marker cannot give an area"

    def start(self, spec: ParamSpec, ctx: StartContext) -> tuple[Any, str | None]:
        areas = [m for m, mk in ctx.markers.items() if mk.kind == "area"]
        if areas:
            return None, areas[0]
        x, y, h = ctx.pose["x"], ctx.pose["y"], self.START_HALF_SIDE
        corners = ((-h, -h), (h, -h), (h, h), (-h, h))
        return [{"x": x + dx, "y": y + dy, "z": 0.0} for dx, dy in corners], None

    def typed(self, v: Any) -> Any:
        return [Position(**p) for p in v]


class Enum(Kind):
    name = "enum"

    def check(
        self, spec: ParamSpec, v: Any, markers: Markers | None, robots: Collection[str] | None
    ) -> list[Problem]:
        choices = spec.choices or []
        if v not in choices:
            what = echo(v) if isinstance(v, str) else describe(v)
            return [((), f"{what} is not one of: {', '.join(choices)}")]
        return []

    def start(self, spec: ParamSpec, ctx: StartContext) -> tuple[Any, str | None]:
        return (spec.choices[0] if spec.choices else None), None


class MarkerRef(Kind):
    name = "marker"
    names_marker = True

    def check(
        self, spec: ParamSpec, v: Any, markers: Markers | None, robots: Collection[str] | None
    ) -> list[Problem]:
        if not isinstance(v, str):
            return [((), f"expected a marker name, got {describe(v)}")]
        if markers is not None and v not in markers:
            return [((), f"unknown marker '{v}' (markers: {', '.join(sorted(markers)) or 'none'})")]
        m = markers.get(v) if markers is not None else None
        if m is not None and spec.marker_kinds and m.kind not in spec.marker_kinds:
            kinds = "/".join(spec.marker_kinds)
            return [((), f"marker '{v}' is a {m.kind} marker; expected {kinds}")]
        return []

    def start(self, spec: ParamSpec, ctx: StartContext) -> tuple[Any, str | None]:
        fit = [
            m
            for m, mk in ctx.markers.items()
            if not spec.marker_kinds or mk.kind in spec.marker_kinds
        ]
        return (fit[0] if fit else None), None


class RobotRef(Kind):
    name = "robot"

    def check(
        self, spec: ParamSpec, v: Any, markers: Markers | None, robots: Collection[str] | None
    ) -> list[Problem]:
        if not isinstance(v, str):
            return [((), f"expected a robot name, got {describe(v)}")]
        if robots is not None and v not in robots:
            return [((), f"unknown robot '{v}' (robots: {', '.join(sorted(robots))})")]
        return []

    def start(self, spec: ParamSpec, ctx: StartContext) -> tuple[Any, str | None]:
        others = [r for r in ctx.robots if r != ctx.robot] or list(ctx.robots)
        return (others[0] if others else None), None


KINDS: dict[str, Kind] = {
    k.name: k
    for k in (
        Bool(),
        Int(),
        Float(),
        Str(),
        List(),
        Dict(),
        PoseKind(),
        PositionKind(),
        AreaKind(),
        Enum(),
        MarkerRef(),
        RobotRef(),
    )
}


def check_value(
    spec: ParamSpec, v: Any, *, markers: Markers | None, robots: Collection[str] | None
) -> list[Problem]:
    """Problems of one value against its spec: [(relative path, sentence)].

    `markers`/`robots` None: references are not checked (library defaults).
    """
    kind = KINDS.get(spec.type)
    if kind is None:
        return [((), f"unknown parameter type {spec.type}")]
    over = value_problem(v)  # a list or dict value holds anything: bound it first
    if over is not None:
        return [(over.path, over.message)]
    return kind.check(spec, v, markers, robots)


def normalize_value(spec: ParamSpec, v: Any) -> Any:
    """Canonical form of a valid value: full poses/positions, floats as floats."""
    return KINDS[spec.type].normalize(spec, v)


def marker_value(spec: ParamSpec, marker: Any) -> tuple[Any, str | None]:
    """Value a marker gives to a bound parameter, or (None, reason it cannot)."""
    return KINDS[spec.type].from_marker(spec, marker)


def starting_values(
    spec_params: Mapping[str, ParamSpec], ctx: StartContext
) -> tuple[dict[str, Any], dict[str, str]]:
    """Values (and marker bindings) for the required parameters without a
    default, so a new skill is valid at once, then edited: the robot's
    position, the first fitting marker, the first choice, the lower bound."""
    params: dict[str, Any] = {}
    bindings: dict[str, str] = {}
    for name, p in spec_params.items():
        if not p.is_required or p.default is not None:
            continue
        value, marker = KINDS[p.type].start(p, ctx)
        if marker is not None:
            bindings[name] = marker
        elif value is not None:
            params[name] = value
    return params, bindings


_POSE_KEYS = frozenset(POSE_FIELDS)
_POSITION_KEYS = frozenset(POSITION_FIELDS)


def typed_by_shape(value: Any) -> Any:
    """The typed value a handler receives, told by the value's shape (a robot
    need not hold the library): a full pose mapping is a `Pose`, a full
    position a `Position`, a list of 3+ positions an area; anything else as is."""
    if isinstance(value, dict):
        keys = set(value)
        if keys == _POSE_KEYS:
            return KINDS["pose"].typed(value)
        if keys == _POSITION_KEYS:
            return KINDS["position"].typed(value)
        return value
    if (
        isinstance(value, list)
        and len(value) >= 3
        and all(isinstance(p, dict) and set(p) == _POSITION_KEYS for p in value)
    ):
        return KINDS["area"].typed(value)
    return value
