"""The plan's forecast and checks, kept current (an object the app owns).

After every change of what the plan reads (a state, a batch, a robot,
telemetry: the model's MISSION, FLEET and TELEMETRY topics), and every
`PLAN_TICK_S` as the clock moves, the plan (`ConsoleModel.plan`,
console/state/plan.py) is refreshed from the model, the map feed's mirror
and the simulator's status; a new forecast is announced as FORECAST (the
timeline, the checks), new findings as FINDINGS (the schedule redraws its
check glyphs and what its sync allows).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from backend.protocol.mapfeed import SimStatus
from console.state.changes import StateChange, Topic, change
from console.state.model import ConsoleModel

PLAN_TICK_S = 0.5
PLAN_INPUTS = frozenset({Topic.MISSION, Topic.FLEET, Topic.TELEMETRY})


class PlanRefresher:
    def __init__(
        self,
        model: ConsoleModel,
        publish: Callable[[StateChange], None],
        sim_status: Callable[[], SimStatus | None] | None = None,
    ) -> None:
        self.model = model
        self._publish = publish
        self._sim_status = sim_status  # None: as set on the plan (tests)
        self._findings_shown = 0

    def start(self, app: Any, changes: Any) -> None:
        """Follow `changes` (at once after each: what the schedule shows
        follows the inputs in order) and the clock (a timer on `app`)."""
        changes.subscribe(app, self._changed)
        self.refresh()
        app.set_interval(PLAN_TICK_S, self.refresh)

    def _changed(self, c: StateChange) -> None:
        if c.topics & PLAN_INPUTS:
            self.refresh()

    def refresh(self, force: bool = False) -> None:
        """Recompute the plan's forecast and checks from what changed."""
        m = self.model
        plan = m.plan
        plan.mirror = m.map_mirror
        if self._sim_status is not None:
            plan.status = self._sim_status()
        new = plan.refresh(m.mission, m.library, m.telemetry, m.clock().timestamp(), force=force)
        topics = [Topic.FORECAST] if new else []
        if plan.findings_generation != self._findings_shown:
            self._findings_shown = plan.findings_generation
            topics.append(Topic.FINDINGS)
        if topics:
            self._publish(change(*topics))
