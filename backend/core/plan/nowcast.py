"""A robot's probable present, from its last report and its plan (the now-cast).

Between two reports of a distant robot the ground knows only the past. The
now-cast walks the robot's course (backend.core.plan.course: its unfinished
skills from its last telemetry, each with its travel, time and energy from the
library's models) for the robot seconds elapsed since that telemetry was
taken: the skill it is probably executing and how far, where it is along its
route (straight from where the skill starts to its goal, travel first), and
its battery (linear over each skill). The active skill lasts what its
telemetry's ETA says when it gives one.

It advances only over skills the robot holds (synchronized) and stops where
the robot would wait: a halted robot (its telemetry says so), a barrier not
passed yet, the end of its queue. Its basis and age say how old what it
starts from is.
"""

from __future__ import annotations

from dataclasses import dataclass

from backend.core.model import Mission, Status
from backend.core.plan.course import Course, Step
from backend.core.plan.geometry import Point

_ON_ROBOT = frozenset(
    {Status.IDLE_SYNCHRONIZED, Status.SYNCHWAITING, Status.RUNNING, Status.PAUSED}
)


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


def nowcast(course: Course, mission: Mission, at: float, speed: float = 1.0) -> Nowcast | None:
    """The robot's probable state at `at` (None: no telemetry to start from).
    `speed`: robot (sim) seconds per wall second."""
    now = course.now
    if now is None:
        return None
    steps = _held(course, mission)
    elapsed = max(0.0, at - now.at) * speed
    base = Nowcast(course.robot, at, now.at, now.skill, now.progress, now.x, now.y, now.battery, "")
    if not steps.steps:
        return _replace(base, held=steps.why)
    return _along(base, steps, elapsed)


@dataclass(frozen=True, slots=True)
class _Steps:
    steps: tuple[Step, ...]  # the ones it may execute from its basis on
    durations: tuple[float, ...]  # robot seconds of each
    why: str  # why it stops after them


def _held(course: Course, mission: Mission) -> _Steps:
    """The steps the robot executes without the ground or a partner, and their durations."""
    now = course.now
    if now is not None and now.mode == "halted":
        return _Steps((), (), "halted")
    out: list[Step] = []
    why = "queue end"
    for i, step in enumerate(course.steps):
        why = _waits(step, i, mission)
        if why:
            break
        out.append(step)
    durations = [st.busy_s for st in out]
    if out and _eta_of(course, out[0]) is not None:
        durations[0] = _eta_of(course, out[0])  # type: ignore[assignment]
    return _Steps(tuple(out), tuple(durations), why or "queue end")


def _waits(step: Step, i: int, mission: Mission) -> str:
    """Why the robot does not go on to step i ('': it does)."""
    s = step.skill
    if s.status not in _ON_ROBOT:
        return "queue end"
    if s.status == Status.PAUSED:
        return "paused"
    return "barrier" if i > 0 and mission.barrier_of(s.id) is not None else ""


def _eta_of(course: Course, step: Step) -> float | None:
    """The robot's own word on how long its active skill still takes."""
    now = course.now
    return now.eta_s if now is not None and now.skill == step.skill.id else None


def _along(base: Nowcast, steps: _Steps, elapsed: float) -> Nowcast:
    """Walk `elapsed` robot seconds along the steps."""
    for step, busy in zip(steps.steps, steps.durations, strict=True):
        if elapsed < busy:
            return _within(base, step, busy, elapsed)
        elapsed -= busy
    last = steps.steps[-1]
    end = last.leg.end if last.leg is not None else None
    return _replace(
        base,
        skill=None,
        progress=None,
        point=end,
        battery=last.battery_end,
        held=steps.why,
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
