"""What the parameter editor tells its screen (Textual messages)."""

from __future__ import annotations

from typing import Any

from textual.message import Message

from backend.core.model import Policies
from backend.core.ops import EditSkill


class ApplyRequested(Message):
    """Apply these changes to a skill: only what differs from it."""

    def __init__(
        self,
        skill_id: str,
        label: str | None,
        params: dict[str, Any],
        bindings: dict[str, str | None],
        base_revision: int,
        policies: Policies | None = None,
    ) -> None:
        super().__init__()
        self.skill_id = skill_id
        self.label = label
        self.params = params
        self.bindings = bindings
        self.base_revision = base_revision
        self.policies = policies

    def operation(self) -> EditSkill:
        return EditSkill(
            id=self.skill_id,
            label=self.label,
            params=self.params,
            bindings=self.bindings,
            policies=self.policies,
        )

    def changed(self) -> list[str]:
        """What the operation changes (for the status line), each once: a
        typed value replacing a binding changes both for one parameter."""
        label = ["label"] if self.label is not None else []
        policies = ["policies"] if self.policies is not None else []
        return list(dict.fromkeys([*self.params, *self.bindings, *label, *policies]))


class DraftsChanged(Message):
    """Which skills have unapplied changes; `discarded`: sentences about
    drafts dropped because their skill left idle or was deleted."""

    def __init__(self, unapplied: frozenset[str], discarded: list[str]) -> None:
        super().__init__()
        self.unapplied = unapplied
        self.discarded = discarded


class EditorLeft(Message):
    """The operator left the editor (escape)."""
