"""Reading the parameter editor's fields back: what differs from the skill
(parameters, bindings, label, policies) and what is wrong with it, checked
with the server's own checks. Mixed into `ParamEditor`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from textual.widgets import Input

from backend.core.model import Mission, Policies, SkillInstance
from backend.core.params import ParamSpec, check_value, normalize_value
from console.state.model import ConsoleModel
from console.widgets.editor.inputs import BINDABLE_KINDS, read_binding, read_param, read_policies


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


class ReadsEdits:
    model: ConsoleModel

    if TYPE_CHECKING:  # what ParamEditor provides

        @property
        def read_only_reason(self) -> str | None: ...
        def _skill(self) -> tuple[str, SkillInstance] | None: ...
        def _spec(self, skill: SkillInstance) -> Any: ...
        def query_one(self, selector: str, expect_type: Any = None) -> Any: ...

    def collect(self) -> tuple[str | None, dict[str, Any], dict[str, str | None], dict[str, str]]:
        """(label change, params changed, bindings changed, problems per parameter)."""
        found = self._skill()
        if found is None:
            return None, {}, {}, {}
        _, s = found
        spec = self._spec(s)
        try:
            label = self.query_one("#f-label", Input).value
        except Exception:
            label = s.label
        changes = Changes()
        for name, pspec in spec.params.items() if spec is not None else ():
            self._collect_param(changes, s, name, pspec)
        label_change = label if label != s.label else None
        return label_change, changes.params, changes.bindings, changes.problems

    def _collect_param(self, ch: Changes, s: SkillInstance, name: str, pspec: ParamSpec) -> None:
        """One parameter's change (or its problem), as typed or chosen."""
        old_bound = s.bindings.get(name)
        bound = read_binding(self, name) if pspec.type in BINDABLE_KINDS else None
        if bound is not None:
            if bound != old_bound:
                ch.bindings[name] = bound
            return
        value, problem = read_param(self, name, pspec)
        if problem is None and value is not None:
            problem = value_problem(pspec, value, self.model.mission)
        if problem is not None:
            ch.problems[name] = problem
        elif value is None:
            ch.unset(s, name, pspec)
        else:
            norm = normalize_value(pspec, value)
            if old_bound is not None:  # a typed value replaces the binding
                ch.bindings[name] = None
                ch.params[name] = norm
            elif s.params.get(name) != norm:
                ch.params[name] = norm

    def policies_change(self) -> tuple[Policies | None, dict[str, str]]:
        """(new policies if they changed, problems per policy)."""
        found = self._skill()
        if found is None:
            return None, {}
        policies, problems = read_policies(self)
        return (
            policies if policies is not None and policies != found[1].policies else None
        ), problems

    def changed_names(self, *, even_read_only: bool = False) -> list[str]:
        """What differs from the skill (including fields that do not read)."""
        if self._skill() is None or (self.read_only_reason is not None and not even_read_only):
            return []
        label, params, bindings, problems = self.collect()
        policies, policy_problems = self.policies_change()
        names = (["label"] if label is not None else []) + list(
            dict.fromkeys([*params, *bindings, *problems])
        )
        if policies is not None or policy_problems:
            names.append("policies")
        return names

    def is_dirty(self) -> bool:
        return bool(self.changed_names())
