"""Waivers: an operator lets a plan check's finding go up the link anyway.

A waiver names a finding by its stable id (`rule:subject`, see
backend.core.plan.checks) and says why; it is journaled like any
operation, so every console sees it and its log says who gave it. The id
is not checked against the findings of the moment: some checks run only
where the map and telemetry are known (consoles, `ctl check`), not here.
"""

from __future__ import annotations

from typing import Any

from backend.core import events as ev
from backend.core.model import Waiver
from backend.core.ops import Unwaive, Waive
from backend.core.plan.checks import RULE_NAMES
from backend.core.rules.base import Change, Refusal, Rule, Rules


def waive(rules: Rules, op: Waive) -> Change:
    reason = op.reason.strip()
    if not reason:
        raise Refusal("bad_request", f"give a reason for waiving {op.check}")
    rule = op.check.split(":", 1)[0]
    if rule not in RULE_NAMES:
        known = ", ".join(sorted(RULE_NAMES))
        raise Refusal("unknown_check", f"no plan check '{rule}' (checks: {known})")
    old = rules.mission.waivers.get(op.check)
    if old is not None and old.reason == reason:
        return Change([], [], {"check": op.check}, None)  # nothing new: no revision
    undo: Waive | Unwaive = (
        Unwaive(check=op.check) if old is None else Waive(check=op.check, reason=old.reason)
    )
    return Change(
        [ev.WaiverSet(check=op.check, waiver=Waiver(reason=reason))],
        [],
        {"check": op.check},
        undo,
    )


def unwaive(rules: Rules, op: Unwaive) -> Change:
    old = rules.mission.waivers.get(op.check)
    if old is None:
        known = ", ".join(sorted(rules.mission.waivers)) or "none"
        raise Refusal("unknown_waiver", f"no waiver for {op.check} (waivers: {known})")
    return Change(
        [ev.WaiverRemoved(check=op.check)],
        [],
        {"check": op.check},
        Waive(check=op.check, reason=old.reason),
    )


RULES: dict[type[Any], Rule] = {Waive: waive, Unwaive: unwaive}
