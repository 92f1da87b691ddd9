"""The one registry of parameter kinds: what each kind of skill parameter accepts,
its canonical form, what a marker gives it, a starting value for a new skill,
and the typed value a skill handler receives (by the kind sent with the
value, `typed_params`).

Libraries, mission files, the rules, `ctl`, the robot agent and the console all
ask this table (`KINDS[spec.type]`) instead of switching on the kind each on
its own, so a kind behaves the same everywhere.

What a person reads and types is also said here, once (`value_text`,
`value_from_text`): angles — a pose's roll, pitch and yaw, a float whose unit
is `rad` — are read and typed in degrees with the unit shown (`30°`; typed
`30`, `30deg`, `30°` or `0.52rad`), while files and the wire keep radians.
One heading convention everywhere: 0° east, counter-clockwise (90° north).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

from pydantic import Field, model_validator

from backend.core.limits import echo, value_problem
from backend.core.model import (
    AreaMarker,
    ParamType,
    Pose,
    PoseMarker,
    Position,
    PositionMarker,
    Strict,
)

POSE_FIELDS = ("x", "y", "z", "roll", "pitch", "yaw")
POSITION_FIELDS = ("x", "y", "z")

Problem = tuple[tuple[str | int, ...], str]  # (path relative to the value, sentence)
Markers = Mapping[str, Any]  # marker name -> PoseMarker | PositionMarker | AreaMarker


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
        why = self._choices_problem() or self._bounds_problem()
        if why:
            raise ValueError(why)
        return self

    def _choices_problem(self) -> str | None:
        """An enum without choices, or choices on another type."""
        if self.type == "enum" and not self.choices:
            return "an enum parameter needs a non-empty 'choices' list"
        if self.type != "enum" and self.choices is not None:
            return "'choices' only applies to enum parameters"
        return None

    def _bounds_problem(self) -> str | None:
        """Bounds on a type that is not a number, or the wrong way round."""
        if (self.min is not None or self.max is not None) and self.type not in ("int", "float"):
            return "'min'/'max' only apply to int and float parameters"
        if self.min is not None and self.max is not None and self.min > self.max:
            return f"min {self.min} is greater than max {self.max}"
        return None

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


# How an error sentence names a value, by its type (the first of its MRO
# here: a bool is not "an integer", a StrEnum is a string).
_DESCRIBED: dict[type, Callable[[Any], str]] = {
    type(None): lambda v: "nothing (null)",
    bool: lambda v: f"a boolean ({v})",
    int: lambda v: f"an integer ({v})",
    float: lambda v: f"a number ({v})",
    str: lambda v: f"a string ({echo(v)})",
    list: lambda v: "a list",
    dict: lambda v: "a mapping",
}


def describe(v: Any) -> str:
    """What a value is, for an error sentence ('a string ('x')')."""
    for t in type(v).__mro__:
        if t in _DESCRIBED:
            return _DESCRIBED[t](v)
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
        why = _coordinate_problem(v[f]) if f in v else None
        if why is not None:
            out.append(((f,), why))
    return out


def _coordinate_problem(x: Any) -> str | None:
    """What is wrong with a field of a pose, position or area point (it
    must be a finite number)."""
    if not is_number(x):
        return f"expected a number, got {describe(x)}"
    return None if math.isfinite(float(x)) else "expected a finite number"


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

    def text(self, spec: ParamSpec, v: Any) -> str:
        """The value as a person reads it (angles in degrees, unit shown)."""
        unit = spec.unit if spec.unit and is_number(v) else ""
        return f"{number_text(v)}{unit}" if is_number(v) else str(v)

    def parse_text(self, spec: ParamSpec, v: Any) -> tuple[Any, str | None]:
        """A value as a person typed it (text, or what YAML made of it) ->
        (the wire's value, None) or (None, what is wrong): angles are read
        in degrees unless they say `rad`. Other checks are `check`'s."""
        return v, None


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


def _range_problem(spec: ParamSpec, v: float) -> str | None:
    """A number not finite, or out of its parameter's bounds."""
    if not math.isfinite(float(v)):
        return "expected a finite number"
    if spec.min is not None and v < spec.min:
        return f"{_given_text(spec, v)} is below the minimum {bound_text(spec, spec.min)}"
    if spec.max is not None and v > spec.max:
        return f"{_given_text(spec, v)} is above the maximum {bound_text(spec, spec.max)}"
    return None


def _given_text(spec: ParamSpec, v: float) -> str:
    """A value as given (`2.0 m/s`: bounds are short, `1 m/s`); angles in degrees."""
    return angle_text(v) if is_angle(spec) else f"{v}{' ' + spec.unit if spec.unit else ''}"


class _Number(Kind):
    integer: ClassVar[bool]
    numeric = True

    def check(
        self, spec: ParamSpec, v: Any, markers: Markers | None, robots: Collection[str] | None
    ) -> list[Problem]:
        why = self.type_problem(v) or _range_problem(spec, v)
        return [((), why)] if why else []

    def type_problem(self, v: Any) -> str | None:
        """What is wrong with a value that is not of this kind of number."""
        raise NotImplementedError

    def start(self, spec: ParamSpec, ctx: StartContext) -> tuple[Any, str | None]:
        v = spec.min if spec.min is not None else 0
        if spec.max is not None:
            v = min(v, spec.max)
        return (int(v) if self.integer else float(v)), None


class Int(_Number):
    name, integer = "int", True

    def type_problem(self, v: Any) -> str | None:
        if isinstance(v, int) and not isinstance(v, bool):
            return None
        return f"expected an integer, got {describe(v)}"


class Float(_Number):
    name, integer = "float", False

    def type_problem(self, v: Any) -> str | None:
        return None if is_number(v) else f"expected a number, got {describe(v)}"

    def normalize(self, spec: ParamSpec, v: Any) -> Any:
        return float(v)

    def text(self, spec: ParamSpec, v: Any) -> str:
        if is_angle(spec) and is_number(v):
            return angle_text(v)
        return super().text(spec, v)

    def parse_text(self, spec: ParamSpec, v: Any) -> tuple[Any, str | None]:
        return parse_angle(v) if is_angle(spec) else (v, None)


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

    def text(self, spec: ParamSpec, v: Any) -> str:
        return pose_text(v) if isinstance(v, dict) else str(v)

    def parse_text(self, spec: ParamSpec, v: Any) -> tuple[Any, str | None]:
        return pose_from_text(v)


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

    def text(self, spec: ParamSpec, v: Any) -> str:
        return pose_text(v) if isinstance(v, dict) else str(v)

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


def _marker_kind_problem(spec: ParamSpec, name: str, m: Any) -> str | None:
    """Marker `name` is not of a kind the parameter takes."""
    if m is None or not spec.marker_kinds or m.kind in spec.marker_kinds:
        return None
    return f"marker '{name}' is a {m.kind} marker; expected {'/'.join(spec.marker_kinds)}"


class MarkerRef(Kind):
    name = "marker"
    names_marker = True

    def check(
        self, spec: ParamSpec, v: Any, markers: Markers | None, robots: Collection[str] | None
    ) -> list[Problem]:
        if not isinstance(v, str):
            return [((), f"expected a marker name, got {describe(v)}")]
        if markers is None:  # no markers to check against (a library's default)
            return []
        if v not in markers:
            return [((), f"unknown marker '{v}' (markers: {', '.join(sorted(markers)) or 'none'})")]
        why = _marker_kind_problem(spec, v, markers[v])
        return [((), why)] if why else []

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


# -- what a person reads and types ---------------------------------------------------

ANGLE_UNITS = frozenset({"rad", "radian", "radians"})  # a float in one of these is an angle
ANGLE_FIELDS = ("roll", "pitch", "yaw")  # a pose's angles
DEGREE_DIGITS = 2  # degrees are shown to 0.01°: a value shown and typed back is the same
HEADING_CONVENTION = "0° east, counter-clockwise (90° north)"
_ANGLE_RE = re.compile(
    r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(°|deg|degrees?|rad|radians?)?\s*$",
    re.IGNORECASE,
)


def is_angle(spec: ParamSpec) -> bool:
    """A float parameter in radians: read and typed in degrees."""
    return spec.type == "float" and spec.unit.strip().lower() in ANGLE_UNITS


def bound_text(spec: ParamSpec, v: float) -> str:
    """A value or bound of a number parameter with its unit: `7.5 m/s`, `190°`."""
    if is_angle(spec):
        return angle_text(v)
    return f"{v:g}{' ' + spec.unit if spec.unit else ''}"


def shown_unit(spec: ParamSpec) -> str:
    """The unit a person reads and types the parameter in (° for angles)."""
    return "°" if is_angle(spec) else spec.unit


def number_text(v: Any) -> str:
    """A number as a person reads it: `2`, `0.5`, `1e+06`."""
    if isinstance(v, bool) or not is_number(v):
        return str(v)
    return f"{v:g}" if isinstance(v, float) else str(v)


def degrees(rad: float) -> float:
    """Radians -> degrees as shown (rounded to DEGREE_DIGITS, no -0)."""
    d = round(math.degrees(rad), DEGREE_DIGITS)
    return d + 0.0 if d else 0.0


def angle_number(rad: float) -> str:
    """An angle in degrees without the unit, for a field whose label says °: `22.92`."""
    return f"{degrees(rad):g}"


def angle_text(rad: float) -> str:
    """An angle as a person reads it: `30°`, `-22.92°`."""
    return f"{angle_number(rad)}°"


def parse_angle(v: Any) -> tuple[float | None, str | None]:
    """(radians, None) from what a person typed, or (None, what is wrong).
    A bare number is in degrees (the unit shown); `30deg`, `30°` and
    `0.52rad` say their unit."""
    if is_number(v):
        return _radians(float(v), "°")
    m = _ANGLE_RE.match(v) if isinstance(v, str) else None
    if m:
        return _radians(float(m.group(1)), (m.group(2) or "°").lower())
    shown = v.strip() if isinstance(v, str) else describe(v)
    return None, f"expected an angle in degrees (30, 30deg or 0.52rad), got {shown!r}"


def _radians(number: float, unit: str) -> tuple[float | None, str | None]:
    """An angle in `unit` (`rad`, else degrees) in radians, if it is finite."""
    if not math.isfinite(number):
        return None, "expected a finite angle"
    return (number if unit.startswith("rad") else math.radians(number)), None


def pose_text(v: Mapping[str, Any]) -> str:
    """`(3,4)` and the other fields that are not 0: `(3,4 z=1 yaw=90°)`."""
    extra = [
        f"{k}={angle_text(v[k]) if k in ANGLE_FIELDS else number_text(v[k])}"
        for k in ("z", *ANGLE_FIELDS)
        if is_number(v.get(k)) and v.get(k)
    ]
    xy = f"{number_text(v.get('x', 0))},{number_text(v.get('y', 0))}"
    return f"({xy}{' ' + ' '.join(extra) if extra else ''})"


def pose_from_text(v: Any) -> tuple[Any, str | None]:
    """A pose mapping as typed: its roll, pitch and yaw in degrees (or with
    their unit) -> radians; other fields as they are (`check` judges them)."""
    if not isinstance(v, dict):
        return v, None
    out = dict(v)
    for k in ANGLE_FIELDS:
        if k in out:
            rad, problem = parse_angle(out[k])
            if problem is not None:
                return None, f"{k}: {problem}"
            out[k] = rad
    return out, None


def value_text(spec: ParamSpec, v: Any) -> str:
    """A parameter's value as a person reads it (angles in degrees)."""
    kind = KINDS.get(spec.type)
    return kind.text(spec, v) if kind is not None else str(v)


def value_from_text(spec: ParamSpec, v: Any) -> tuple[Any, str | None]:
    """A parameter's value as a person typed it -> (wire value, None) or
    (None, what is wrong): angles typed in degrees become radians."""
    kind = KINDS.get(spec.type)
    return kind.parse_text(spec, v) if kind is not None else (v, None)


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


def typed_params(values: Mapping[str, Any], kinds: Mapping[str, str]) -> dict[str, Any]:
    """A skill's parameters as its handler receives them: every parameter of
    `kinds` (its kind from the library, sent with the values), each value
    typed by its kind (`Kind.typed`: a pose a `Pose`, an area a list of
    `Position`); one left unset is None. Values without a kind (a server
    that sends none) are passed as they came: nothing is guessed."""
    out = dict(values)
    for name, kind in kinds.items():
        value = values.get(name)
        known = KINDS.get(kind)
        out[name] = known.typed(value) if known is not None and value is not None else value
    return out
