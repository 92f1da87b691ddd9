"""The app's part of the plan's timeline and checks: their screens (F7, F8)
and the timer that keeps the forecast and the checks current.

A mixin of `MissionApp` (console/app.py), which calls `add_plan_modes` when
it is made and `start_plan` when it is mounted. After each change the app
announces on its awareness signal (a state, events, telemetry), and every
`PLAN_TICK_S` as the clock moves, the plan (`ConsoleModel.plan`,
console/state/plan.py) is refreshed from the model, the map feed's mirror
and the simulator's status; when its forecast or findings changed, the app
says so ("plan") and the schedule redraws its check glyphs and what its
sync allows.
"""

from __future__ import annotations

from typing import Any

from console.screens.checks import ChecksScreen
from console.screens.timeline import TimelineScreen

PLAN_TICK_S = 0.5


class PlanModes:
    model: Any
    awareness_signal: Any
    map_feed: Any
    bridge: Any
    mission_screen: Any
    clock: Any

    def add_plan_modes(self: Any) -> None:
        changes = self.awareness_signal
        self.add_mode("timeline", lambda: TimelineScreen(self.model, changes))
        self.add_mode("checks", lambda: ChecksScreen(self.model, changes))

    def start_plan(self: Any) -> None:
        # after every change the app announces (state, events, telemetry, fleet): at once,
        # so what the schedule shows follows the messages in order; the timer moves the clock
        self.awareness_signal.subscribe(self, self._plan_inputs_changed)
        self.refresh_plan()
        self.set_interval(PLAN_TICK_S, self.refresh_plan)

    def _plan_inputs_changed(self: Any, change: tuple[str, str | None]) -> None:
        if change[0] in ("fleet", "log"):
            self.call_next(self.refresh_plan)

    def refresh_plan(self: Any, force: bool = False) -> None:
        """Recompute the plan's forecast and checks from what changed."""
        plan, m = self.model.plan, self.model
        if self.map_feed is not None:
            plan.mirror = self.map_feed[0]
        if self.bridge is not None:  # else as set (tests)
            plan.status = self.bridge.sim_status
        if plan.refresh(m.mission, m.library, m.telemetry, self.clock().timestamp(), force=force):
            self.awareness_signal.publish(("plan", None))
        # the schedule shows the findings (glyphs, what sync allows), not the forecast
        if plan.findings_generation != getattr(self, "_findings_shown", 0) and self._screen_live():
            self._findings_shown = plan.findings_generation
            self.mission_screen.plan_changed()

    def action_show_timeline(self: Any) -> None:
        self.switch_mode("timeline")

    def action_show_checks(self: Any) -> None:
        self.switch_mode("checks")
