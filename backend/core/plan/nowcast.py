"""A robot's probable present, from its last report and its plan (the now-cast).

Between two reports of a distant robot the ground knows only the past. The
now-cast walks the robot's course (backend.core.plan.course: its unfinished
skills from its last telemetry, each with its travel, time and energy from the
library's models) for the robot seconds elapsed since that telemetry was
taken: the skill it is probably executing and how far, where it is along its
route (straight from where the skill starts to its goal, travel first), and
its battery (linear over each skill). The active skill lasts what its
telemetry's ETA says when it gives one.

It advances over the skills the robot holds and those a pending sync carries
(from when the sync reaches it: the link's delay and windows), and stops
where the robot would wait: halted or idle without a run since (a pending
run counts from when it arrives), paused, a barrier not passed yet, the end
of its queue. Its basis and age say how old what it starts from is.
"""

from __future__ import annotations

from dataclasses import dataclass

from backend.core.model import CommandState, Mission, SkillInstance, Status, UplinkCommand
from backend.core.plan.course import Course, Step
from backend.core.plan.geometry import Point
from backend.core.plan.inputs import LinkModel

_ON_ROBOT = frozenset(
    {Status.IDLE_SYNCHRONIZED, Status.SYNCHWAITING, Status.RUNNING, Status.PAUSED}
)
_CONTROLS = frozenset({"run", "pause", "stop", "reset"})
_STILL = frozenset({"halted", "idle"})  # modes in which it executes only after a run
_NEVER = frozenset({CommandState.REFUSED, CommandState.EXPIRED, CommandState.CANCELLED})
_NO_LINK = LinkModel()


@dataclass(frozen=True, slots=True)
class Nowcast:
    robot: str
    at: float  # the instant predicted (wall seconds, POSIX)
    basis: float  # when the telemetry it starts from was taken
    skill: str | None  # the skill it probably executes (None: none)
    progress: float | None  # of that skill, 0..1
    x: float | None
    y: float | None
    battery: float | None
    held: str  # why it stopped advancing: "", "halted", "paused", "barrier", "queue end"

    @property
    def age_s(self) -> float:
        """Wall seconds between its basis and the instant predicted."""
        return self.at - self.basis

    def as_json(self) -> dict[str, object]:
        return {f: getattr(self, f) for f in self.__slots__} | {"age_s": self.age_s}


def nowcast(
    course: Course,
    mission: Mission,
    at: float,
    speed: float = 1.0,
    link: LinkModel = _NO_LINK,
) -> Nowcast | None:
    """The robot's probable state at `at` (None: no telemetry to start from).
    `speed`: robot (sim) seconds per wall second; `link`: when what the ground
    sent reaches the robot (a pending sync's skills, a pending run)."""
    now = course.now
    if now is None:
        return None
    base = Nowcast(course.robot, at, now.at, now.skill, now.progress, now.x, now.y, now.battery, "")
    uplink = _Uplink(mission, course.robot, now.at, link)
    start = uplink.runs_from(now.mode)
    steps = _held(course, mission, uplink)
    if start is None or not steps.steps:
        return _replace(base, held="halted" if start is None else steps.why)
    return _along(base, steps, start, at, speed)


class _Uplink:
    """What the ground sent the robot that it may have by now, and when it got it."""

    def __init__(self, mission: Mission, robot: str, basis: float, link: LinkModel) -> None:
        self.mission, self.basis, self.link = mission, basis, link
        self.locks = mission.command_locks()
        controls = [c for c in mission.uplink.get(robot, []) if c.op in _CONTROLS]
        self.control = controls[-1] if controls else None

    def arrives(self, c: UplinkCommand) -> float:
        """When the robot had (or will have) the command, wall seconds."""
        if c.answered is not None:
            return c.answered.timestamp() - self.link.one_way_s
        return self.link.reaches((c.sent or c.created).timestamp())

    def runs_from(self, mode: str) -> float | None:
        """From when the robot executes its queue (None: it waits for a run)."""
        if mode not in _STILL:
            return self.basis
        c = self.control
        if c is None or c.op != "run" or c.state in _NEVER:
            return None
        arrives = self.arrives(c)
        return max(self.basis, arrives) if c.pending or arrives >= self.basis else None

    def earliest(self, s: SkillInstance) -> float | None:
        """When a skill reaches the robot (0: it holds it; None: it never will)."""
        if s.status in _ON_ROBOT:
            return 0.0
        c = self.locks.get(s.id)
        return self.arrives(c) if c is not None and c.op == "sync" else None


@dataclass(frozen=True, slots=True)
class _Steps:
    steps: tuple[Step, ...]  # the ones it may execute from its basis on
    durations: tuple[float, ...]  # robot seconds of each
    earliest: tuple[float, ...]  # when each reaches the robot (wall)
    why: str  # why it stops after them


def _held(course: Course, mission: Mission, uplink: _Uplink) -> _Steps:
    """The steps the robot executes without a partner or the operator, and their durations."""
    out: list[Step] = []
    earliest: list[float] = []
    why = ""
    for i, step in enumerate(course.steps):
        when = uplink.earliest(step.skill)
        why = "queue end" if when is None else _waits(step, i, mission)
        if why:
            break
        out.append(step)
        earliest.append(when or 0.0)
    durations = [st.busy_s for st in out]
    if out and _eta_of(course, out[0]) is not None:
        durations[0] = _eta_of(course, out[0])  # type: ignore[assignment]
    return _Steps(tuple(out), tuple(durations), tuple(earliest), why or "queue end")


def _waits(step: Step, i: int, mission: Mission) -> str:
    """Why the robot does not go on to step i ('': it does)."""
    if step.skill.status == Status.PAUSED:
        return "paused"
    return "barrier" if i > 0 and mission.barrier_of(step.skill.id) is not None else ""


def _eta_of(course: Course, step: Step) -> float | None:
    """The robot's own word on how long its active skill still takes."""
    now = course.now
    return now.eta_s if now is not None and now.skill == step.skill.id else None


def _along(base: Nowcast, steps: _Steps, start: float, at: float, speed: float) -> Nowcast:
    """Walk the steps on the wall clock from `start` to `at`."""
    cursor = start
    for step, busy, earliest in zip(steps.steps, steps.durations, steps.earliest, strict=True):
        begin = max(cursor, earliest)
        if at < begin:  # it waits for the skill to reach it
            return _replace(base, skill=None, progress=None, point=step.start, held="uplink")
        cursor = begin + busy / speed
        if at < cursor:
            return _within(base, step, busy, (at - begin) * speed)
    last = steps.steps[-1]
    end = last.leg.end if last.leg is not None else None
    return _replace(
        base, skill=None, progress=None, point=end, battery=last.battery_end, held=steps.why
    )


def _within(base: Nowcast, step: Step, busy: float, t: float) -> Nowcast:
    """`t` robot seconds into a step that lasts `busy`."""
    share = t / busy if busy > 0 else 1.0
    progress = (1.0 - step.remaining) + step.remaining * share
    return _replace(
        base,
        skill=step.skill.id,
        progress=min(1.0, progress),
        point=_place(step, busy, t),
        battery=_lerp(step.battery_start, step.battery_end, share),
    )


def _place(step: Step, busy: float, t: float) -> Point | None:
    """Travel first, in a straight line from where the step starts to its goal."""
    leg = step.leg
    if leg is None or leg.goal is None or step.start is None:
        return step.start if leg is None else leg.end
    share = _share(t, step.travel_s * _scale(busy, step.busy_s))
    (x0, y0), (x1, y1) = step.start, leg.goal
    return (x0 + (x1 - x0) * share, y0 + (y1 - y0) * share)


def _scale(busy: float, modelled: float) -> float:
    """How much longer the step lasts than the models say (the robot's ETA)."""
    return busy / modelled if modelled > 0 else 0.0


def _share(t: float, span: float) -> float:
    return min(1.0, t / span) if span > 0 else 1.0


def _lerp(a: float | None, b: float | None, share: float) -> float | None:
    if a is None or b is None:
        return a
    return a + (b - a) * share


def _replace(base: Nowcast, point: Point | None = None, **changes: object) -> Nowcast:
    fields = {f: getattr(base, f) for f in base.__slots__} | changes
    if point is not None:
        fields["x"], fields["y"] = point
    return Nowcast(**fields)
