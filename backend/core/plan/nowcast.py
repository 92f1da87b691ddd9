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

from collections.abc import Mapping
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
    # why it is not executing a skill: "", "halted" (no run), "waiting" (for a skill to
    # reach it, or for a partner), "paused", "barrier" (never passed), "queue end"
    held: str

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
    """One robot's probable state at `at` (None: no telemetry to start from);
    its barriers wait for partners it is not told about: they hold it."""
    return nowcasts({course.robot: course}, mission, at, speed, {course.robot: link})[course.robot]


def nowcasts(
    courses: Mapping[str, Course],
    mission: Mission,
    at: float,
    speed: float = 1.0,
    links: Mapping[str, LinkModel] | None = None,
) -> dict[str, Nowcast | None]:
    """Each robot's probable state at `at` (None: no telemetry to start from).
    `speed`: robot (sim) seconds per wall second; `links`: when what the ground
    sent reaches each robot (a pending sync's skills, a pending run). A barrier
    passes when every partner's walk has reached it."""
    walks = {
        r: _walk(c, mission, (links or {}).get(r, _NO_LINK), speed) for r, c in courses.items()
    }
    _barriers(walks, mission)
    return {r: w.state_at(at) if w is not None else None for r, w in walks.items()}


def _walk(course: Course, mission: Mission, link: LinkModel, speed: float) -> _Walk | None:
    now = course.now
    if now is None:
        return None
    uplink = _Uplink(mission, course.robot, now.at, link)
    base = Nowcast(
        course.robot, 0.0, now.at, now.skill, now.progress, now.x, now.y, now.battery, ""
    )
    start = uplink.runs_from(now.mode)
    steps = _held(course, mission, uplink)
    w = _Walk(base, steps, start if start is not None else now.at, speed)
    w.halted = start is None and bool(steps.steps)  # it has skills, and waits for a run
    if not w.halted:
        w.lay()
    return w


def _barriers(walks: Mapping[str, _Walk | None], mission: Mission) -> None:
    """Pass every barrier all of whose robots' walks wait at it, until none moves."""
    going = [w for w in walks.values() if w is not None]
    while _pass_one(going, mission):
        pass


def _pass_one(walks: list[_Walk], mission: Mission) -> bool:
    """Pass one barrier whose robots all wait at it; whether one passed."""
    for b in {w.barrier for w in walks} - {None}:
        there = [w for w in walks if w.barrier == b]
        if len(there) == len(mission.barriers[b].skills):  # type: ignore[index]
            at = max(w.cursor for w in there)
            for w in there:
                w.pass_barrier(at)
            return True
    return False


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
    barriers: tuple[str | None, ...]  # the barrier each waits at first (None: none)
    why: str  # why it stops after them


def _held(course: Course, mission: Mission, uplink: _Uplink) -> _Steps:
    """The steps the robot executes without the operator, and their durations."""
    out, earliest, why = _reachable(course, uplink)
    durations = [st.busy_s for st in out]
    eta = _eta_of(course, out[0]) if out else None
    if eta is not None:
        durations[0] = eta
    barriers = [_barrier(st, i, mission) for i, st in enumerate(out)]
    return _Steps(tuple(out), tuple(durations), tuple(earliest), tuple(barriers), why)


def _reachable(course: Course, uplink: _Uplink) -> tuple[list[Step], list[float], str]:
    """The steps the robot has or will have in order, when each reaches it, why no more."""
    out: list[Step] = []
    earliest: list[float] = []
    for step in course.steps:
        when = uplink.earliest(step.skill)
        why = "queue end" if when is None else _waits(step)
        if why:
            return out, earliest, why
        out.append(step)
        earliest.append(when or 0.0)
    return out, earliest, "queue end"


def _barrier(step: Step, i: int, mission: Mission) -> str | None:
    """The barrier the step waits at first (its active skill's: only while it waits)."""
    if i == 0 and step.skill.status != Status.SYNCHWAITING:
        return None
    return mission.barrier_of(step.skill.id)


def _waits(step: Step) -> str:
    """Why the robot does not go on to the step ('': it does)."""
    return "paused" if step.skill.status == Status.PAUSED else ""


def _eta_of(course: Course, step: Step) -> float | None:
    """The robot's own word on how long its active skill still takes."""
    now = course.now
    return now.eta_s if now is not None and now.skill == step.skill.id else None


class _Walk:
    """A robot's steps laid on the wall clock, up to a barrier not passed yet."""

    def __init__(self, base: Nowcast, steps: _Steps, start: float, speed: float) -> None:
        self.base, self.steps, self.cursor, self.speed = base, steps, start, speed
        self.laid: list[tuple[float, float]] = []  # (begin, end) of each step laid
        self.passed: set[int] = set()  # steps whose barrier passed
        self.halted = False

    @property
    def barrier(self) -> str | None:
        """The barrier it waits at (None: it does not)."""
        k = len(self.laid)
        return self.steps.barriers[k] if k < len(self.steps.steps) else None

    def lay(self) -> None:
        for k in range(len(self.laid), len(self.steps.steps)):
            if self.steps.barriers[k] is not None and k not in self.passed:
                return
            begin = max(self.cursor, self.steps.earliest[k])
            self.cursor = begin + self.steps.durations[k] / self.speed
            self.laid.append((begin, self.cursor))

    def pass_barrier(self, at: float) -> None:
        self.passed.add(len(self.laid))
        self.cursor = max(self.cursor, at)
        self.lay()

    def state_at(self, at: float) -> Nowcast:
        base = _replace(self.base, at=at)
        if self.halted:
            return _replace(base, held="halted")
        for step, busy, (begin, end) in zip(
            self.steps.steps, self.steps.durations, self.laid, strict=False
        ):
            if at < begin:  # it waits for the skill to reach it, or for a partner
                return _replace(base, skill=None, progress=None, point=step.start, held="waiting")
            if at < end:
                return _within(base, step, busy, (at - begin) * self.speed)
        return self._after(base)

    def _after(self, base: Nowcast) -> Nowcast:
        """Past every step laid: at the end of the last one, waiting."""
        held = "barrier" if self.barrier is not None else self.steps.why
        if not self.laid:
            return _replace(base, held=held)
        last = self.steps.steps[len(self.laid) - 1]
        end = last.leg.end if last.leg is not None else None
        return _replace(
            base, skill=None, progress=None, point=end, battery=last.battery_end, held=held
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
