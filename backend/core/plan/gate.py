"""The sync gate: skills with unwaived plan errors do not go up the link.

Called by the Sync rule (backend.core.rules.execution.plan_sync) with the
skills about to be sent. The mission server knows the mission and the
library, not the site map nor the robots' telemetry, so it runs the checks
that need neither: barrier deadlocks and orphans, parameters, and energy from
an assumed full battery (a plan that empties even a full battery). Consoles
and `ctl check` run every check with the map and telemetry they follow, and
a console refuses locally what its fuller view finds.
"""

from __future__ import annotations

import time
from collections.abc import Iterable

from backend.core.plan.checks import Finding, run_checks
from backend.core.plan.inputs import PlanInputs
from backend.core.rules.base import Refusal, Rules

MAX_NAMED = 3  # findings spelled out in one refusal


def blocking(findings: Iterable[Finding], ids: Iterable[str]) -> list[Finding]:
    """The unwaived errors that name one of the skills `ids`."""
    sending = set(ids)
    return [f for f in findings if f.blocking and sending.intersection(f.skills)]


def refusal(robot: str, found: list[Finding]) -> Refusal:
    said = "; ".join(f"{f.id}: {f.message}" for f in found[:MAX_NAMED])
    more = f" (and {len(found) - MAX_NAMED} more)" if len(found) > MAX_NAMED else ""
    return Refusal(
        "plan_errors",
        f"cannot synchronize {robot}: {len(found)} unwaived plan error(s): {said}{more}. Fix the "
        "plan, or waive each with `missionctl ctl waive CHECK_ID --reason TEXT` (or from the "
        "console's checks screen, F8)",
        robot=robot,
        skill=found[0].skills[0] if found[0].skills else None,
    )


def check_sync(rules: Rules, robot: str, ids: list[str]) -> None:
    """Refuse sending `ids` to `robot` while an unwaived error names one of them."""
    inputs = PlanInputs(now=time.time())
    findings = run_checks(rules.mission, rules.library, inputs, robots={robot})
    found = blocking(findings, ids)
    if found:
        raise refusal(robot, found)
