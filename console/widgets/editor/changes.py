"""Reading the parameter editor's form back: what differs from the skill
(parameters, bindings, label, policies) and what is wrong with it, checked
with the server's own checks. Functions of the form (the editor, a DOM node
whose fields they query) and of the skill it shows."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from textual.dom import DOMNode
from textual.widgets import Input

from backend.core.library import SkillSpec
from backend.core.model import Mission, Policies, SkillInstance
from backend.core.params import ParamSpec, check_value, normalize_value
from console.widgets.editor.inputs import (
    BINDABLE_KINDS,
    Reading,
    read_binding,
    read_param,
    read_policies,
)

# (label change, params changed, bindings changed, problems per parameter)
Collected = tuple[str | None, dict[str, Any], dict[str, str | None], dict[str, str]]


@dataclass
class Changes:
    """What differs from the skill: parameters (None: back to the default),
    bindings (None: unbound) and the problems per parameter."""

    params: dict[str, Any] = field(default_factory=dict)
    bindings: dict[str, str | None] = field(default_factory=dict)
    problems: dict[str, str] = field(default_factory=dict)

    def unset(self, s: SkillInstance, name: str, spec: ParamSpec) -> None:
        """The parameter's field is empty."""
        if spec.is_required:
            self.problems[name] = f"missing required {spec.type} parameter '{name}'"
        elif name in s.params and (
            spec.default is None or s.params[name] != normalize_value(spec, spec.default)
        ):
            self.params[name] = None  # back to the default

    def typed(self, s: SkillInstance, name: str, spec: ParamSpec, value: Any) -> None:
        """A value typed (or chosen) for the parameter."""
        norm = normalize_value(spec, value)
        if s.bindings.get(name) is not None:  # a typed value replaces the binding
            self.bindings[name] = None
            self.params[name] = norm
        elif s.params.get(name) != norm:
            self.params[name] = norm


def value_problem(spec: ParamSpec, value: Any, mission: Mission | None) -> str | None:
    """The first problem the server's own check finds with a typed value."""
    m = mission
    found = check_value(
        spec, value, markers=m.markers if m else None, robots=set(m.robots) if m else None
    )
    if not found:
        return None
    rel, msg = found[0]
    where = ".".join(str(x) for x in rel)
    return f"{where}: {msg}" if where else msg


def collect(
    form: DOMNode, s: SkillInstance, spec: SkillSpec | None, mission: Mission | None
) -> Collected:
    """What the form changes of skill `s`, and what is wrong with it."""
    try:
        label = form.query_one("#f-label", Input).value
    except Exception:  # being rebuilt
        label = s.label
    changes = Changes()
    for name, pspec in spec.params.items() if spec is not None else ():
        _collect_param(form, changes, s, name, pspec, mission)
    label_change = label if label != s.label else None
    return label_change, changes.params, changes.bindings, changes.problems


def _collect_param(
    form: DOMNode,
    ch: Changes,
    s: SkillInstance,
    name: str,
    pspec: ParamSpec,
    mission: Mission | None,
) -> None:
    """One parameter's change (or its problem), as typed or chosen."""
    bound = read_binding(form, name) if pspec.type in BINDABLE_KINDS else None
    if bound is not None:
        if bound != s.bindings.get(name):
            ch.bindings[name] = bound
        return
    value, problem = _checked(form, name, pspec, mission)
    if problem is not None:
        ch.problems[name] = problem
    elif value is None:
        ch.unset(s, name, pspec)
    else:
        ch.typed(s, name, pspec, value)


def _checked(form: DOMNode, name: str, pspec: ParamSpec, mission: Mission | None) -> Reading:
    """(value, problem) of a parameter as typed, checked as the server would."""
    value, problem = read_param(form, name, pspec)
    if problem is None and value is not None:
        problem = value_problem(pspec, value, mission)
    return value, problem


def policies_change(form: DOMNode, s: SkillInstance) -> tuple[Policies | None, dict[str, str]]:
    """(the new policies if they changed, problems per policy)."""
    policies, problems = read_policies(form)
    return (policies if policies is not None and policies != s.policies else None), problems


def changed_names(
    form: DOMNode, s: SkillInstance, spec: SkillSpec | None, mission: Mission | None
) -> list[str]:
    """What differs from the skill (including fields that do not read)."""
    label, params, bindings, problems = collect(form, s, spec, mission)
    policies, policy_problems = policies_change(form, s)
    names = (["label"] if label is not None else []) + list(
        dict.fromkeys([*params, *bindings, *problems])
    )
    if policies is not None or policy_problems:
        names.append("policies")
    return names
