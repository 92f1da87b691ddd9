"""The plan's forecast and checks as this console sees them — no Textual here.

`PlanView` keeps a `Forecaster` (backend.core.plan) fed with what the console
has: the mirrored mission and library, the robots' telemetry, the map feed's
mirror and the simulator's status (speed, link delay). `refresh` recomputes
what its inputs changed since the last call: the app calls it on a timer, so
an edit shows within a tick and the clock pass follows the time. The checks
run again on every change of the plan or the map, and on telemetry alone at
most every `CHECKS_EVERY_S`; a map update (which makes every leg cold) counts
at most every `MAP_EVERY_S`.
"""

from __future__ import annotations

from collections.abc import Mapping

from backend.client.planning import MirrorSite, plan_inputs
from backend.core.library import Library
from backend.core.model import Mission, SkillInstance, Status
from backend.core.plan.checks import Finding, run_checks
from backend.core.plan.forecast import Forecast, Forecaster
from backend.core.plan.inputs import PlanInputs
from backend.protocol.mapfeed import MapMirror, SimStatus
from backend.protocol.messages import Telemetry
from console.state.nowcast import NowcastView

CHECKS_EVERY_S = 2.0
MAP_EVERY_S = 5.0
RANK = {"error": 0, "warning": 1}


def _rank(f: Finding) -> tuple[int, int]:
    """Most severe first: unwaived errors, warnings, then waived findings."""
    return (f.waiver is not None, RANK[f.severity])


class PlanView:
    def __init__(self) -> None:
        self.forecast: Forecast | None = None
        self.findings: list[Finding] = []
        self.marks: dict[str, Finding] = {}  # skill id -> its most severe finding
        self.mirror: MapMirror | None = None  # the map feed's, set by the app
        self.status: SimStatus | None = None  # the simulator's, set by the app
        # skill id -> (start, end) its forecast had when it was synchronized (the
        # timeline draws the plan under what happened): a review reads them from
        # the journal, a console keeps those of its own syncs
        self.planned: dict[str, tuple[float, float]] = {}
        self.generation = 0  # grows with every new forecast
        self.nowcast = NowcastView()  # each robot's probable present, from the forecast
        self.findings_generation = 0  # grows when the findings (or their waivers) change
        self._forecaster: Forecaster | None = None
        self._library: Library | None = None
        self._site: MirrorSite | None = None
        self._seen: tuple[object, ...] | None = None
        self._checked: tuple[object, ...] | None = None
        self._checked_at = -1e18
        self._map_at = -1e18
        self._map_key: object = None

    # -- recomputing ----------------------------------------------------------------------
    def _site_now(self, now: float) -> object:
        """The map's key, moved on at most every MAP_EVERY_S."""
        if self.mirror is None or not self.mirror.ready:
            self._site = None
            return None
        if self._site is None or self._site.mirror is not self.mirror:
            self._site = MirrorSite(self.mirror)
            self._map_key, self._map_at = None, -1e18
        if now - self._map_at >= MAP_EVERY_S:
            version = self._site.version
            if version != self._map_key:
                self._map_key, self._map_at = version, now
        return self._map_key

    def refresh(
        self,
        mission: Mission | None,
        library: Library | None,
        telemetry: Mapping[str, Telemetry],
        now: float,
        *,
        force: bool = False,
    ) -> bool:
        """Recompute what changed; True when there is a new forecast (the
        findings may be the same: `findings_generation` says)."""
        if mission is None or library is None:
            changed = self.forecast is not None
            self.forecast = None
            self._set_findings([])
            return changed
        if library is not self._library:
            self._library, self._forecaster = library, Forecaster(library)
        plan = (id(mission), mission.revision, id(library))
        site = self._site_now(now)
        status = (self.status.speed, self.status.link_delay_s) if self.status else None
        seen = (plan, tuple((r, id(t)) for r, t in telemetry.items()), site, status, int(now))
        if seen == self._seen and not force:
            return False
        self._seen = seen
        inputs = plan_inputs(now, telemetry, self._site if site is not None else None, self.status)
        assert self._forecaster is not None
        self.nowcast.reported(self.forecast, mission, telemetry, self.status)
        self.forecast = self._forecaster.forecast(mission, inputs)
        self._check((plan, site, status), mission, library, inputs, now, force)
        self.generation += 1
        return True

    def _check(
        self,
        checked: tuple[object, ...],
        mission: Mission,
        library: Library,
        inputs: PlanInputs,
        now: float,
        force: bool,
    ) -> None:
        """The plan checks, again when the plan, the map or the sim changed
        (or every CHECKS_EVERY_S: what they read of the present moves on)."""
        if force or checked != self._checked or now - self._checked_at >= CHECKS_EVERY_S:
            self._checked, self._checked_at = checked, now
            self._set_findings(run_checks(mission, library, inputs, forecast=self.forecast))

    def inputs(self, telemetry: Mapping[str, Telemetry], now: float) -> PlanInputs:
        """What the last forecast was made with, at `now` (allocation hints)."""
        site = self._site if self._map_key is not None else None
        return plan_inputs(now, telemetry, site, self.status)

    def _set_findings(self, findings: list[Finding]) -> None:
        if [(f.id, f.message, f.waiver) for f in findings] != [
            (f.id, f.message, f.waiver) for f in self.findings
        ]:
            self.findings_generation += 1
        self.findings = findings
        self.marks = _marks(findings)

    # -- what the screens ask ------------------------------------------------------------------
    @property
    def link_delay_s(self) -> float:
        """The one-way delay in wall seconds (the timeline's clock; the sim's is sim time)."""
        st = self.status
        return st.link_delay_s / (st.speed if st.speed > 0 else 1.0) if st is not None else 0.0

    def mark(self, skill_id: str) -> Finding | None:
        return self.marks.get(skill_id)

    def blocking(self, task: list[SkillInstance], through: str) -> list[Finding]:
        """The unwaived errors that refuse a sync of `task` through `through`
        (the skills it would send: the unsynchronized head down to it)."""
        sending: set[str] = set()
        for s in task:
            if s.status == Status.IDLE:
                sending.add(s.id)
            if s.id == through:
                break
        return [f for f in self.findings if f.blocking and sending.intersection(f.skills)]

    def counts(self) -> tuple[int, int, int]:
        """(unwaived errors, warnings, waived)."""
        errors = sum(f.blocking for f in self.findings)
        waived = sum(f.waiver is not None for f in self.findings)
        return errors, len(self.findings) - errors - waived, waived


def _marks(findings: list[Finding]) -> dict[str, Finding]:
    """skill -> the finding its row shows: the most severe on it."""
    marks: dict[str, Finding] = {}
    for f in findings:
        for sid in f.skills:
            if sid not in marks or _rank(f) < _rank(marks[sid]):
                marks[sid] = f
    return marks
