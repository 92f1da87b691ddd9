"""The inputs of a parameter, by kind: a table (`INPUT_KINDS`) of how each kind
of parameter is composed into input widgets and read back from them.

bool: a switch, with its value in words; int, float, str: a text input; pose:
six number fields, position: three; area, list and dict: YAML text; enum,
marker and robot: a choice (of the spec's choices, the markers of the allowed
kinds, the mission's robots). Pose, position and area parameters can also be
bound to a marker (`bind_select`). Below them, the skill's policies.

Angles (a pose's roll, pitch and yaw; a float in `rad`) are shown and typed in
degrees, the unit in the label (`yaw°`); `0.5rad` and `30deg` say their unit
(backend.core.params.parse_angle). A field left as shown keeps the exact
value it showed (degrees are rounded for reading).

Widget ids: `f-<param>` (`f-<param>-<field>` for coordinates), `v-<param>`
(a switch's value in words), `bind-<param>`; policies `pf-`, `pv-`, `perr-`.
Reading raises nothing: a value, or a sentence saying what is wrong.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import yaml
from pydantic import ValidationError
from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.dom import DOMNode
from textual.widgets import Input, Label, Select, Static, Switch, TextArea

from backend.core.model import Mission, Policies, SkillInstance
from backend.core.params import (
    ANGLE_FIELDS,
    POSE_FIELDS,
    POSITION_FIELDS,
    ParamSpec,
    angle_number,
    is_angle,
    parse_angle,
    shown_unit,
)
from backend.files import yamlio
from console.state.text import fmt_number
from console.widgets.editor.contingency import (
    CONTINGENCY_HINTS,
    contingency_input,
    read_contingency,
)
from console.widgets.editor.fields import FieldArea, FieldInput, FieldSelect, FieldSwitch

TYPED = "\x00typed"  # the bind choice meaning "no marker: a typed value"
BINDABLE_KINDS = {"pose": ("pose", "position"), "position": ("pose", "position"), "area": ("area",)}
# policy -> (label, type hint); bounds and meaning come from backend.core.model.Policies
POLICY_HINTS = {
    "retries": ("retries", "int 0..20"),
    "pause_out_of_comms": ("pause out of comms", "bool"),
    "recharge_below": ("recharge below", "float 0..1, empty: off"),
} | CONTINGENCY_HINTS
INPUTS = "Input, Switch, Select, TextArea"  # what holds a value (drafts keep them)

Reading = tuple[Any, str | None]  # (value, None: unset), or (None, what is wrong)


def widget_value(w: Any) -> Any:
    return w.text if isinstance(w, TextArea) else w.value


def set_widget_value(w: Any, value: Any) -> None:
    if isinstance(w, TextArea):
        w.text = value
    else:
        w.value = value


def yaml_text(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, list) and value and all(isinstance(x, dict) for x in value):
        return "\n".join(
            "- " + yaml.safe_dump(x, default_flow_style=True, sort_keys=False).strip()
            for x in value
        )
    return yaml.safe_dump(
        value, default_flow_style=False, sort_keys=False, allow_unicode=True
    ).strip()


def _bounds(spec: ParamSpec) -> str:
    """'0.1..1', '..5', '' (none); angles in degrees."""
    if spec.min is None and spec.max is None:
        return ""

    def bound(b: float | None) -> str:
        if b is None:
            return ""
        return angle_number(b) if is_angle(spec) else f"{b:g}"

    return f"{bound(spec.min)}..{bound(spec.max)}"


def spec_hint(spec: ParamSpec) -> str:
    """type, unit and bounds: 'float m/s 0.1..1', 'float ° -180..180'."""
    kinds = "/".join(spec.marker_kinds or []) if spec.type == "marker" else ""
    parts = [spec.type, shown_unit(spec), _bounds(spec), kinds]
    return " ".join([p for p in parts if p] + (["required"] if spec.is_required else []))


@dataclass(frozen=True)
class Field:
    """One parameter to compose inputs for."""

    name: str
    spec: ParamSpec
    value: Any
    disabled: bool
    mission: Mission | None


# -- composing, by kind -------------------------------------------------------------------


def _switch(f: Field) -> ComposeResult:
    with Horizontal(classes="fields"):
        yield FieldSwitch(bool(f.value), id=f"f-{f.name}", disabled=f.disabled)
        yield Label("yes" if f.value else "no", id=f"v-{f.name}", classes="switch-value")


TEXT_TYPES = {"int": "integer", "float": "number", "str": "text"}  # kind -> Input type


class AngleInput(FieldInput):
    """An angle in degrees (typed `30`, `30deg` or `0.52rad`); remembers the
    value it was shown with, so a field left as shown keeps it exactly."""

    def __init__(self, radians: float | None, **kw: Any) -> None:
        self.shown = "" if radians is None else angle_number(radians)
        self.original = radians
        super().__init__(self.shown, **kw)

    def radians(self) -> Reading:
        """(radians, None), (None, None) when empty, or (None, what is wrong)."""
        raw = self.value.strip()
        if not raw:
            return None, None
        if raw == self.shown and self.original is not None:
            return self.original, None
        return parse_angle(raw)


def _text(f: Field) -> ComposeResult:
    t = f.spec.type
    v = f.value
    if is_angle(f.spec):
        rad = float(v) if isinstance(v, int | float) and not isinstance(v, bool) else None
        yield AngleInput(
            rad, id=f"f-{f.name}", compact=True, disabled=f.disabled, placeholder="degrees"
        )
        return
    text = "" if v is None else (fmt_number(v) if t != "str" else str(v))
    yield FieldInput(
        text, id=f"f-{f.name}", type=TEXT_TYPES[t], compact=True, disabled=f.disabled, placeholder=t
    )


def _coordinate_rows(kind: str) -> list[tuple[str, ...]]:
    """A pose's six fields on two rows, a position's three on one."""
    return [POSE_FIELDS[:3], POSE_FIELDS[3:]] if kind == "pose" else [POSITION_FIELDS]


def _coordinates(f: Field) -> ComposeResult:
    """A pose's six fields, a position's three; empty when the parameter is
    unset (an optional one: empty fields read back as unset, not as 0)."""
    v = f.value if isinstance(f.value, dict) else None
    for row in _coordinate_rows(f.spec.type):
        with Horizontal(classes="fields"):
            for c in row:
                x = float(v.get(c, 0.0)) if v is not None else None
                if c in ANGLE_FIELDS:  # degrees, the unit in the label
                    yield Label(f"{c}°")
                    yield AngleInput(
                        x, id=f"f-{f.name}-{c}", compact=True, disabled=f.disabled, placeholder="–"
                    )
                    continue
                yield Label(c)
                yield FieldInput(
                    "" if x is None else fmt_number(x),
                    id=f"f-{f.name}-{c}",
                    type="number",
                    compact=True,
                    disabled=f.disabled,
                    placeholder="–",
                )


def _yaml(f: Field) -> ComposeResult:
    yield FieldArea(
        yaml_text(f.value),
        id=f"f-{f.name}",
        compact=True,
        disabled=f.disabled,
        soft_wrap=True,
        tab_behavior="focus",
    )


def _marker_choices(f: Field) -> list[str]:
    """The mission's markers of the kinds the parameter takes (any, when it names none)."""
    kinds = f.spec.marker_kinds
    markers = f.mission.markers if f.mission else {}
    return [mk for mk, marker in markers.items() if not kinds or marker.kind in kinds]


# what a choice offers, by parameter kind
CHOICES: dict[str, Callable[[Field], list[str]]] = {
    "enum": lambda f: list(f.spec.choices or []),
    "marker": _marker_choices,
    "robot": lambda f: list(f.mission.robots) if f.mission else [],
}


def _choices(f: Field) -> list[str]:
    return CHOICES[f.spec.type](f)


def _choice(f: Field) -> ComposeResult:
    choices = _choices(f)
    if isinstance(f.value, str) and f.value not in choices:
        choices.append(f.value)
    yield FieldSelect(
        [(c, c) for c in choices],
        value=f.value if f.value in choices else Select.NULL,
        allow_blank=True,
        prompt="(default)" if not f.spec.is_required else "choose…",
        id=f"f-{f.name}",
        compact=True,
        disabled=f.disabled,
    )


# -- reading back, by kind ----------------------------------------------------------------


def _read_switch(root: DOMNode, name: str, spec: ParamSpec) -> Reading:
    return root.query_one(f"#f-{name}", Switch).value, None


def _read_text(root: DOMNode, name: str, spec: ParamSpec) -> Reading:
    return root.query_one(f"#f-{name}", Input).value, None


def _read_number(root: DOMNode, name: str, spec: ParamSpec) -> Reading:
    field = root.query_one(f"#f-{name}", Input)
    if isinstance(field, AngleInput):
        return field.radians()
    raw = field.value.strip()
    if not raw:
        return None, None
    integer = spec.type == "int"
    try:
        return (int(raw) if integer else float(raw)), None
    except ValueError:
        return None, f"expected {'an integer' if integer else 'a number'}, got '{raw}'"


def _read_coordinates(root: DOMNode, name: str, spec: ParamSpec) -> Reading:
    fields = {
        c: root.query_one(f"#f-{name}-{c}", Input)
        for row in _coordinate_rows(spec.type)
        for c in row
    }
    if not any(w.value.strip() for w in fields.values()):
        return None, None  # all empty: unset
    out: dict[str, float] = {}
    for c, field in fields.items():
        value, problem = _coordinate(field)
        if problem is not None:
            return None, f"{c}: {problem}"
        out[c] = value
    return out, None


def _coordinate(field: Input) -> Reading:
    """One coordinate as typed (an empty field is 0), or what is wrong with it."""
    if isinstance(field, AngleInput):
        rad, problem = field.radians()
        return (rad if rad is not None else 0.0), problem
    raw = field.value.strip()
    try:
        return (float(raw) if raw else 0.0), None
    except ValueError:
        return None, f"expected a number, got '{raw}'"


def _read_yaml(root: DOMNode, name: str, spec: ParamSpec) -> Reading:
    raw = root.query_one(f"#f-{name}", TextArea).text
    if not raw.strip():
        return None, None
    try:  # within the file limits: an alias bomb typed here is measured, never expanded
        return yamlio.load(raw).data, None
    except yamlio.YamlSyntaxError as e:
        problem = e.message.removeprefix("YAML syntax error: ")
        return None, f"not valid YAML (line {e.line}): {problem}"


def _read_choice(root: DOMNode, name: str, spec: ParamSpec) -> Reading:
    v = root.query_one(f"#f-{name}", Select).value
    return (None if v is Select.NULL else v), None


@dataclass(frozen=True)
class InputKind:
    compose: Callable[[Field], ComposeResult]
    read: Callable[[DOMNode, str, ParamSpec], Reading]


SWITCH = InputKind(_switch, _read_switch)
NUMBER = InputKind(_text, _read_number)
COORDINATES = InputKind(_coordinates, _read_coordinates)
YAML_TEXT = InputKind(_yaml, _read_yaml)
CHOICE = InputKind(_choice, _read_choice)

# parameter kind (backend.core.params.ParamType) -> its inputs
INPUT_KINDS: dict[str, InputKind] = {
    "bool": SWITCH,
    "int": NUMBER,
    "float": NUMBER,
    "str": InputKind(_text, _read_text),
    "pose": COORDINATES,
    "position": COORDINATES,
    "area": YAML_TEXT,
    "list": YAML_TEXT,
    "dict": YAML_TEXT,
    "enum": CHOICE,
    "marker": CHOICE,
    "robot": CHOICE,
}


def bind_select(
    name: str, kind: str, bound: str | None, mission: Mission, disabled: bool
) -> FieldSelect:
    """The choice of a marker to bind a pose, position or area parameter to."""
    kinds = BINDABLE_KINDS[kind]
    options = [("typed value", TYPED)] + [
        (f"@{mk}  ({marker.kind})", mk)
        for mk, marker in mission.markers.items()
        if marker.kind in kinds
    ]
    if bound and bound not in mission.markers:
        options.append((f"@{bound} (missing)", bound))
    return FieldSelect(
        options,
        value=bound or TYPED,
        allow_blank=False,
        id=f"bind-{name}",
        compact=True,
        disabled=disabled,
        classes="bind",
    )


def param_inputs(
    name: str, spec: ParamSpec, s: SkillInstance, mission: Mission | None, *, disabled: bool
) -> ComposeResult:
    """The inputs of one parameter of skill `s` (a bound one's typed value is disabled)."""
    bound = s.bindings.get(name)
    if spec.type in BINDABLE_KINDS and mission is not None:
        yield bind_select(name, spec.type, bound, mission, disabled)
        disabled = disabled or bool(bound)
    kind = INPUT_KINDS.get(spec.type)
    if kind is None:
        yield Static(f"unsupported type {spec.type}", classes="perror")
        return
    yield from kind.compose(Field(name, spec, s.params.get(name), disabled, mission))


def read_param(root: DOMNode, name: str, spec: ParamSpec) -> Reading:
    """(value, problem) of one parameter as typed; value None = unset."""
    kind = INPUT_KINDS.get(spec.type)
    if kind is None:
        return None, f"unsupported type {spec.type}"
    try:
        return kind.read(root, name, spec)
    except Exception as e:  # the widgets are being rebuilt
        return None, f"cannot read the field ({type(e).__name__})"


def read_binding(root: DOMNode, name: str) -> str | None:
    """The marker a parameter is bound to (None: a typed value)."""
    try:
        v = root.query_one(f"#bind-{name}", Select).value
    except Exception:
        return None
    return None if v in (TYPED, Select.NULL) else str(v)


# -- policies ---------------------------------------------------------------------------------


def policy_inputs(p: Policies, *, disabled: bool) -> ComposeResult:
    yield Static("policies — applied by the robot itself", classes="section")
    for name, hint in POLICY_HINTS.items():
        if name == next(iter(CONTINGENCY_HINTS)):
            yield Static("Contingency — decided on board, no round trip", classes="section")
        yield from _policy_group(name, hint, p, disabled)


def _policy_group(name: str, hint: tuple[str, str], p: Policies, disabled: bool) -> ComposeResult:
    label, kind = hint
    with Vertical(classes="param", id=f"policy-{name}"):
        yield Label(Text.assemble((label, "bold"), ("  " + kind, "dim")), classes="plabel")
        yield from _policy_input(name, p, disabled)
        yield Static(Policies.model_fields[name].description or "", classes="pdesc")
        yield Static("", id=f"perr-{name}", classes="perror -empty")


def _policy_input(name: str, p: Policies, disabled: bool) -> ComposeResult:
    if name in CONTINGENCY_HINTS:
        yield from contingency_input(name, p, disabled)
    elif name == "pause_out_of_comms":
        with Horizontal(classes="fields"):
            yield FieldSwitch(p.pause_out_of_comms, id=f"pf-{name}", disabled=disabled)
            yield Label(
                "yes" if p.pause_out_of_comms else "no", id=f"pv-{name}", classes="switch-value"
            )
    elif name == "retries":
        yield FieldInput(
            str(p.retries),
            id=f"pf-{name}",
            type="integer",
            compact=True,
            disabled=disabled,
            placeholder="0",
        )
    else:
        text = "" if p.recharge_below is None else fmt_number(p.recharge_below)
        yield FieldInput(
            text, id=f"pf-{name}", type="number", compact=True, disabled=disabled, placeholder="off"
        )


def read_policies(root: DOMNode) -> tuple[Policies | None, dict[str, str]]:
    """The policies as typed (None if unreadable) and problems per policy."""
    try:
        pause = root.query_one("#pf-pause_out_of_comms", Switch).value
        retries = root.query_one("#pf-retries", Input).value.strip()
        below = root.query_one("#pf-recharge_below", Input).value.strip()
    except Exception:  # not composed (no skill, or being rebuilt)
        return None, {}
    raw: dict[str, Any] = {"pause_out_of_comms": pause}
    problems: dict[str, str] = {}
    for name, (value, problem) in (
        ("retries", _retries(retries)),
        ("recharge_below", _recharge_below(below)),
    ):
        if problem is None:
            raw[name] = value
        else:
            problems[name] = problem
    more, bad = read_contingency(root)
    if problems or bad:
        return None, problems | bad
    return _policies(raw | more)


def _retries(raw: str) -> Reading:
    try:
        return (int(raw) if raw else 0), None
    except ValueError:
        return None, f"expected an integer, got '{raw}'"


def _recharge_below(raw: str) -> Reading:
    if raw.lower() in ("", "off"):
        return None, None
    try:
        return float(raw), None
    except ValueError:
        return None, f"expected a number between 0 and 1 (empty: off), got '{raw}'"


def _policies(raw: dict[str, Any]) -> tuple[Policies | None, dict[str, str]]:
    """The policies checked by the protocol's own model: the same bounds the server checks."""
    try:
        return Policies(**raw), {}
    except ValidationError as e:
        problems = {}
        for err in e.errors():
            name = str(err["loc"][0]) if err["loc"] else "retries"
            problems[name] = f"{err['input']!r}: {err['msg'].removeprefix('Input ')}"
        return None, problems
