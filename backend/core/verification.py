"""A command's verification stages, each with the time its evidence is due at the ground.

queued -> sent -> received -> started -> completed, read from what the ground holds:
- queued: the command is in its robot's uplink (from `created`);
- sent: a transmission left that may have reached the robot (`sent`);
- received: the robot's answer says it applied it (`acked` = received; `refused`,
  `expired`, `cancelled` fail it);
- started: the first of its skills the robot reports running (sync and retry only:
  the other commands concern no skill to execute);
- completed: every one of its skills ended; all succeeded, else it failed.

A stage's *due* is when its evidence should reach the ground, on the wall clock
(the one every stamp is on; a reader turns it into mission time): the command
leaves when the robot is next in contact, reaches it one delay later, and its
answer comes back when the robot is in contact again, one delay later. A
skill starts when the plan's forecast (sent with the sync) said, or once the
robot has the command if that is later, and only in run mode: a robot halted
(no run, or a pause, stop or reset since) starts nothing before the next run
reaches it, and none on its way means no start is due; it ends the forecast's duration after
it actually started; its report comes back as the answer does. No forecast, or
no contact ahead: no due (nothing to be late against). A stage not reached
`tolerance_s` after its due is *overdue*.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Final, Literal

from pydantic import Field

from backend.core.model import (
    CommandOp,
    CommandState,
    Mission,
    Name,
    SkillId,
    SkillInstance,
    Status,
    Strict,
    UplinkCommand,
)
from backend.core.ops import Predicted

StageName = Literal["queued", "sent", "received", "started", "completed"]
STAGES: Final[tuple[StageName, ...]] = ("queued", "sent", "received", "started", "completed")
# ok: reached; waiting: not yet, not late; overdue: not reached tolerance_s after its due;
# failed: it never will be (refused, expired, a skill failed); none: does not apply
StageState = Literal["ok", "waiting", "overdue", "failed", "none"]

TOLERANCE_MIN_S: Final = 2.0  # wall seconds: the downlink's own pace, a busy loop
TOLERANCE_SHARE: Final = 0.1  # of the time from the command's creation to the due
EXECUTES: Final = frozenset({"sync", "retry"})  # the commands whose skills start and complete
_FAIL_STATES = frozenset({CommandState.REFUSED, CommandState.EXPIRED, CommandState.CANCELLED})
_MODE_OPS = frozenset({"run", "pause", "stop", "reset"})  # what sets the robot's run mode
_UNSTARTED = frozenset({Status.IDLE, Status.IDLE_SYNCHRONIZED, Status.SYNCHWAITING})


class Stage(Strict):
    name: StageName
    state: StageState
    at: datetime | None = Field(None, description="when it was reached (or failed)")
    due: datetime | None = Field(
        None, description="when its evidence is due at the ground (None: no due)"
    )
    tolerance_s: float = Field(0.0, ge=0, description="how late past its due it is overdue")

    def late(self, now: datetime, grace_s: float = 0.0) -> bool:
        """Past its due by more than its tolerance and `grace_s` (reached or not)."""
        allowed = self.tolerance_s + grace_s
        return self.due is not None and (now - self.due).total_seconds() > allowed


class Verification(Strict):
    """A command's stages, in order."""

    command: int = Field(ge=1)
    robot: Name
    op: CommandOp
    skills: list[SkillId] = Field(default_factory=list, max_length=10_000)
    stages: list[Stage] = Field(max_length=len(STAGES))

    def stage(self, name: StageName) -> Stage:
        return self.stages[STAGES.index(name)]

    @property
    def current(self) -> Stage | None:
        """The first stage not reached yet that still may be (None: settled)."""
        return next((s for s in self.stages if s.state in ("waiting", "overdue")), None)

    @property
    def failed(self) -> bool:
        return any(s.state == "failed" for s in self.stages)


@dataclass(frozen=True)
class Path:
    """The link to a robot as verification needs it: the one-way delay (wall
    seconds) and the first instant at or after a time when the robot is in
    contact (None: never, e.g. offline or no window ahead)."""

    delay_s: float = 0.0
    open_from: Callable[[datetime], datetime | None] = lambda t: t


def tolerance_s(c: UplinkCommand, due: datetime | None) -> float:
    """How late a stage may be: a floor, and a share of how far ahead its due was."""
    ahead = 0.0 if due is None else max(0.0, (due - c.created).total_seconds())
    return TOLERANCE_MIN_S + TOLERANCE_SHARE * ahead


def watched(c: UplinkCommand) -> list[str]:
    """The skills whose start and end verify the command: those the robot says
    it queued once it answered, else those it was sent (sync and retry only)."""
    if c.op not in EXECUTES:
        return []
    if c.state == CommandState.ACKED:
        return list(c.done)
    return list(c.skills)


def verify(
    c: UplinkCommand,
    mission: Mission,
    path: Path,
    forecast: Mapping[str, Predicted],
    now: datetime,
    grace_s: float = 0.0,
) -> Verification:
    """The command's stages at `now` (`grace_s`: more tolerance, a reader's own)."""
    timing = _Timing(c, path)
    skills = _Skills(c, mission)
    stages = [
        Stage(name="queued", state="ok", at=c.created),
        _sent(c, timing.back),
        _received(c, timing.back),
        *_execution(c, skills, timing, skills.plan(forecast)),
    ]
    return Verification(
        command=c.id,
        robot=c.robot,
        op=c.op,
        skills=skills.ids() or list(c.skills),
        stages=[_judged(s, now, c, grace_s) for s in stages],
    )


class _Timing:
    """When the command can reach the robot, and when the robot's word can come back."""

    def __init__(self, c: UplinkCommand, path: Path) -> None:
        self.path = path
        self.delay = timedelta(seconds=path.delay_s)
        # from when it left (a robot not heard yet when it was queued gets it later)
        self.on_robot = self.returns(c.sent or c.created)
        if c.answered is not None:  # it reached the robot: its answer says when (its clock)
            self.on_robot = c.answered
        self.back = self.returns(self.on_robot)

    def returns(self, t: datetime | None) -> datetime | None:
        """When something sent at `t` (or as soon as the robot is in contact) arrives."""
        opens = None if t is None else self.path.open_from(t)
        return None if opens is None else opens + self.delay


class _Skills:
    """The skills a command executes, as the mission has them now."""

    def __init__(self, c: UplinkCommand, mission: Mission) -> None:
        self.mission = mission
        self.skills = [f[2] for f in filter(None, map(mission.find, watched(c)))]
        self.asked = _asked(mission, c.robot, set(self.ids()))
        # applied, then taken back (unsynchronized) before they started: they never will
        self.withdrawn = c.state == CommandState.ACKED and self.all_in({Status.IDLE})

    def ids(self) -> list[str]:
        return [s.id for s in self.skills]

    def plan(self, forecast: Mapping[str, Predicted]) -> list[Predicted]:
        return [forecast[i] for i in self.ids() if i in forecast]

    def all_in(self, statuses: set[Status]) -> bool:
        return bool(self.skills) and all(s.status in statuses for s in self.skills)

    def any_failed(self) -> bool:
        return any(s.status == Status.FAILURE for s in self.skills)

    def started(self) -> datetime | None:
        return min(filter(None, map(_start_of, self.skills)), default=None)

    def ended(self) -> datetime | None:
        return max(filter(None, (s.finished_at for s in self.skills)), default=None)


def _asked(mission: Mission, robot: str, ids: set[str]) -> timedelta:
    """How long the skills waited, or may wait, on the operators: each question
    from its asking to its end (an open one: to its default). The forecast
    does not know of questions; without this a robot that waits for an answer
    would be said overdue."""
    waits = [
        (q.closed or q.due) - q.asked for q in mission.questions.get(robot, []) if q.skill in ids
    ]
    return sum(waits, timedelta(0))


def _start_of(s: SkillInstance) -> datetime | None:
    """When it started (a skill that failed before running: when it ended)."""
    return None if s.status in _UNSTARTED else s.started_at or s.finished_at


def _sent(c: UplinkCommand, due: datetime | None) -> Stage:
    if c.sent is not None:
        return Stage(name="sent", state="ok", at=c.sent, due=due)
    return Stage(name="sent", state=_RECEIVED.get(c.state, "waiting"), at=c.settled, due=due)


def _received(c: UplinkCommand, due: datetime | None) -> Stage:
    state = _RECEIVED.get(c.state, "waiting")
    return Stage(name="received", state=state, at=c.answered or c.settled, due=due)


# a command's state -> its received stage (queued and sent: waiting)
_RECEIVED: dict[CommandState, StageState] = {
    CommandState.ACKED: "ok",
    **dict.fromkeys(_FAIL_STATES, "failed"),
}


def _executes(c: UplinkCommand) -> bool:
    return c.op in EXECUTES and not (c.state == CommandState.ACKED and not c.done)


def _execution(
    c: UplinkCommand, skills: _Skills, timing: _Timing, plan: list[Predicted]
) -> list[Stage]:
    """The started and completed stages (none for a command that executes nothing)."""
    if not _executes(c):
        return [Stage(name="started", state="none"), Stage(name="completed", state="none")]
    if c.state in _FAIL_STATES:
        return [Stage(name="started", state="failed"), Stage(name="completed", state="failed")]
    runs = timing.on_robot if skills.started() else _runs_from(c, skills.mission, timing)
    start_due, end_due = _execution_dues(plan, timing, runs, skills.started(), skills.asked)
    return [_start_stage(skills, start_due), _end_stage(skills, end_due)]


def _runs_from(c: UplinkCommand, mission: Mission, timing: _Timing) -> datetime | None:
    """When the robot may start the command's skills: once it has them, if it
    is in run mode then (the last run, pause, stop or reset it applied before
    them was a run), else once the next run reaches it; None while none is on
    its way (it is halted: nothing is late before an operator sends a run)."""
    modes = [
        m
        for m in mission.uplink.get(c.robot, [])
        if m.op in _MODE_OPS and m.state not in _FAIL_STATES
    ]
    before = [m for m in modes if m.seq < c.seq]
    if before and before[-1].op == "run":
        return timing.on_robot
    run = next((m for m in modes if m.seq > c.seq and m.op == "run"), None)
    if run is None or timing.on_robot is None:
        return None
    run_on = _Timing(run, timing.path).on_robot
    return None if run_on is None else max(timing.on_robot, run_on)


def _execution_dues(
    plan: list[Predicted],
    timing: _Timing,
    runs: datetime | None,
    started: datetime | None,
    asked: timedelta,
) -> tuple[datetime | None, datetime | None]:
    """When word of the start and of the end is due: the plan's times, later if
    the robot could run them later (`runs`); the end moves with the actual
    start and with the time its skills waited on questions (`asked`)."""
    if not plan or runs is None:
        return None, None
    planned = min(p.start for p in plan)
    expected = max(planned, runs)
    shift = max((started or expected) - planned, timedelta(0)) + asked
    return timing.returns(expected), timing.returns(max(p.end for p in plan) + shift)


def _start_stage(skills: _Skills, due: datetime | None) -> Stage:
    at = skills.started()
    if at is not None:
        return Stage(name="started", state="ok", at=at, due=due)
    return Stage(name="started", state="failed" if skills.withdrawn else "waiting", due=due)


def _end_stage(skills: _Skills, due: datetime | None) -> Stage:
    if skills.all_in({Status.SUCCESS}):
        return Stage(name="completed", state="ok", at=skills.ended(), due=due)
    if skills.withdrawn or skills.any_failed():
        return Stage(name="completed", state="failed", at=skills.ended(), due=due)
    return Stage(name="completed", state="waiting", due=due)


def _judged(s: Stage, now: datetime, c: UplinkCommand, grace_s: float) -> Stage:
    """Its tolerance; a waiting stage past its due and its tolerance is overdue."""
    if s.due is None:
        return s
    s = s.model_copy(update={"tolerance_s": round(tolerance_s(c, s.due) + grace_s, 3)})
    return s.model_copy(update={"state": "overdue"}) if s.state == "waiting" and s.late(now) else s


def late_s(s: Stage, now: datetime) -> float:
    """How far past its due a stage is (wall seconds; 0 if not)."""
    return 0.0 if s.due is None else max(0.0, (now - s.due).total_seconds())


def under_way(c: UplinkCommand, mission: Mission) -> bool:
    """Whether a command is still being verified: pending, or a sync/retry the
    robot applied whose skills have not all ended (nor been taken back)."""
    if c.pending:
        return True
    if c.state != CommandState.ACKED or c.op not in EXECUTES:
        return False
    return any(_executing(mission, sid) for sid in c.done)


def _executing(mission: Mission, skill_id: str) -> bool:
    found = mission.find(skill_id)
    return found is not None and found[2].status not in _NOT_EXECUTING


_NOT_EXECUTING = frozenset({Status.SUCCESS, Status.FAILURE, Status.IDLE})
