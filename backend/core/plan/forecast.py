"""Predicted start and end of every unfinished skill, across robots.

Each robot's course (backend.core.plan.course) gives how long its skills
take; here they are laid on the clock: a skill starts when the one before it
ends, a skill that is not on the robot yet no earlier than a command sent
now can reach it (the link's delay and contact windows), a queued skill of a
halted robot likewise (it needs a `run`), and a barrier's skills when the
last of their robots gets there (the others wait). The active skill ends
when its telemetry says (its ETA), else when the model says, never before
now. Skills after a barrier that is never passed have no prediction.

The clock pass works on *segments*: runs of skills that follow each other
without a wait (cut at the active skill, at the first unsynchronized one and
at barrier skills), so it costs per robot the number of barriers, not of
skills. A skill's times are its segment's start plus the robot seconds
before it in the course, looked up when asked (`Forecast.skill`).

`Forecaster` keeps the legs, courses and segments of the last call: an event
or a telemetry sample recomputes only the robots it touched.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field

from backend.core.library import Library
from backend.core.model import ACTIVE, FINISHED, Mission, SkillInstance, Status
from backend.core.plan.branches import BranchCost
from backend.core.plan.course import Course, LegCache, Step, walk
from backend.core.plan.inputs import PlanInputs
from backend.core.plan.order import BarrierAnalysis, analyse

Span = tuple[float, float]


@dataclass(frozen=True, slots=True)
class SkillForecast:
    id: str
    robot: str
    ready: float  # when the robot could start it (a barrier's skills wait until start)
    start: float
    end: float
    barrier: str | None
    after: str | None  # the skill whose end set its start (None: the clock or the link did)
    battery_start: float | None
    battery_min: float | None
    battery_end: float | None
    out_of_coverage: tuple[Span, ...]  # wall-clock spans out of comms coverage
    skill: SkillInstance = field(compare=False, repr=False)  # as the course saw it
    # the on_timeout its end assumes (its timeout is short), and the branch
    # that would leave the battery lowest (backend.core.plan.branches)
    assumed: BranchCost | None = field(default=None, compare=False)
    worst: BranchCost | None = field(default=None, compare=False)

    @property
    def wait_s(self) -> float:
        return self.start - self.ready


@dataclass(frozen=True, slots=True)
class RobotForecast:
    robot: str
    end: float | None  # its last skill's predicted end (None: never, or nothing planned)
    blocked_at: str | None  # the skill held at a barrier that is never passed
    battery_end: float | None
    battery_assumed: bool  # no telemetry: a full battery was assumed
    halted: bool  # it waits for a run command


@dataclass(slots=True)
class Segment:
    """Steps first..last-1 of a course, one after the other without a wait."""

    first: int
    last: int
    kind: str  # "active" | "queued" | "idle" (the first step is not on the robot yet)
    barrier: str | None  # the first step's barrier
    ready: float = 0.0
    start: float = 0.0
    end: float = 0.0
    after: str | None = None


@dataclass
class Track:
    course: Course
    segments: list[Segment]
    laid: int = 0  # segments on the clock; fewer: held at a barrier never passed
    halted: bool = False

    def segment_of(self, i: int) -> Segment | None:
        for seg in self.segments[: self.laid]:
            if seg.first <= i < seg.last:
                return seg
        return None


@dataclass
class Forecast:
    now: float
    speed: float = 1.0
    tracks: dict[str, Track] = field(default_factory=dict)
    barriers: BarrierAnalysis = field(default_factory=BarrierAnalysis)
    robots: dict[str, RobotForecast] = field(default_factory=dict)
    end: float | None = None  # of the mission (None: never, a barrier is never passed)
    last: str | None = None  # the skill that ends last
    _memo: dict[str, SkillForecast | None] = field(default_factory=dict)

    @property
    def courses(self) -> dict[str, Course]:
        return {r: t.course for r, t in self.tracks.items()}

    def skill(self, sid: str) -> SkillForecast | None:
        """The prediction of an unfinished skill (None: none, or never)."""
        if sid not in self._memo:
            self._memo[sid] = self._predict(sid)
        return self._memo[sid]

    def robot_skills(self, robot: str) -> Iterator[SkillForecast]:
        track = self.tracks.get(robot)
        if track is None:
            return
        for seg in track.segments[: track.laid]:
            for i in range(seg.first, seg.last):
                f = self.skill(track.course.steps[i].skill.id)
                if f is not None:
                    yield f

    def _predict(self, sid: str) -> SkillForecast | None:
        for robot, track in self.tracks.items():
            i = track.course.index.get(sid)
            if i is None:
                continue
            seg = track.segment_of(i)
            if seg is None:
                return None
            return _skill(robot, track, seg, i, self.speed)
        return None

    def window(
        self, robot: str, t0: float, t1: float, step: float = 0.0
    ) -> Iterator[SkillForecast]:
        """The robot's predicted skills overlapping [t0, t1], in order (what a
        timeline shows: found by bisection, not by walking every skill). With
        `step` (seconds per cell of a drawing), at most one skill per cell:
        the first that starts in it."""
        track = self.tracks.get(robot)
        if track is None:
            return
        for seg in track.segments[: track.laid]:
            if seg.end >= t0 and seg.start <= t1:
                yield from self._in_segment(robot, track, seg, (t0, t1), step)

    def _in_segment(
        self, robot: str, track: Track, seg: Segment, span: Span, step: float
    ) -> Iterator[SkillForecast]:
        """The skills of one segment that overlap `span` (with `step`, the
        first of each cell)."""
        t0, t1 = span
        c = track.course
        cells = step > 0 and seg.kind != "active"
        k = self._first_at(c, seg, t0)
        memo = self._memo  # looked up inline: this loop runs per shown skill
        while k < seg.last:
            sid = c.steps[k].skill.id
            f = memo.get(sid)
            if f is None:
                f = memo[sid] = _skill(robot, track, seg, k, self.speed)
            if f.start > t1:
                break
            if f.end >= t0:
                yield f
            k = self._next_cell(c, seg, t0, step, f.start, k) if cells else k + 1

    def _first_at(self, c: Course, seg: Segment, t: float) -> int:
        """The first step of `seg` going on at time t (the active skill's
        segment: its first, which is running now)."""
        if seg.kind != "active" and t > seg.start:
            return self._step_at(c, seg, t, seg.first)
        return seg.first

    def _next_cell(self, c: Course, seg: Segment, t0: float, step: float, t: float, k: int) -> int:
        """The first step after `k` going on in the cell after the one of time `t`."""
        cell_end = t0 + (math.floor((t - t0) / step) + 1) * step
        return max(k + 1, self._step_at(c, seg, cell_end, k + 1))

    def _step_at(self, c: Course, seg: Segment, t: float, lo: int) -> int:
        """The first step of `seg` (from `lo`) still going at time t."""
        at = c.offsets[seg.first] + (t - seg.start) * self.speed
        return max(lo, bisect.bisect_right(c.offsets, at, lo, seg.last) - 1)

    def critical_path(self) -> list[str]:
        """Skill ids, first to last, of the chain that sets the mission's end."""
        out: list[str] = []
        sid = self.last
        seen: set[str] = set()
        while sid is not None and sid not in seen:
            f = self.skill(sid)
            if f is None:
                break
            out.append(sid)
            seen.add(sid)
            sid = f.after
        out.reverse()
        return out

    @property
    def critical_robot(self) -> str | None:
        f = self.skill(self.last) if self.last is not None else None
        return f.robot if f is not None else None

    def summary(self, clock: Callable[[float], str]) -> str:
        """The end in a line, "plan ends 15:42 · critical: lru2" (times by `clock`)."""
        if self.end is None:
            held = sorted(r.robot for r in self.robots.values() if r.blocked_at is not None)
            stuck = ", ".join(sorted(self.barriers.stuck)) or "a barrier"
            return f"plan never ends: {', '.join(held)} held at {stuck}"
        critical = self.critical_robot
        tail = f" · critical: {critical}" if critical is not None else ""
        return f"plan ends {clock(self.end)}{tail}"


def _skill(robot: str, track: Track, seg: Segment, i: int, speed: float) -> SkillForecast:
    c = track.course
    step = c.steps[i]
    if seg.kind == "active":
        start, end = seg.start, seg.end
    else:
        start = seg.start + (c.offsets[i] - c.offsets[seg.first]) / speed
        end = start + step.busy_s / speed
    first = i == seg.first
    return SkillForecast(
        id=step.skill.id,
        robot=robot,
        ready=seg.ready if first else start,
        start=start,
        end=end,
        barrier=seg.barrier if first else None,
        after=seg.after if first else c.steps[i - 1].skill.id,
        battery_start=step.battery_start,
        battery_min=step.battery_min,
        battery_end=step.battery_end,
        out_of_coverage=_spans(step, start, end, speed),
        skill=step.skill,
        assumed=step.assumed,
        worst=step.worst,
    )


def _spans(step: Step, start: float, end: float, speed: float) -> tuple[Span, ...]:
    leg = step.leg
    if leg is None:
        return ()
    travel_end = min(end, start + step.travel_s / speed)
    spans = [
        (start + f0 * (travel_end - start), start + f1 * (travel_end - start))
        for f0, f1 in leg.travel_out
    ]
    if leg.work_out and end > travel_end:
        spans.append((travel_end, end))
    return tuple(spans)


# A step's kind of segment by its status: "active" (running or paused: the
# one on the clock now), "idle" (not on the robot yet), else "queued".
_MOVING = ACTIVE - {Status.SYNCHWAITING}
_KIND = {s: "active" if s in _MOVING else "idle" if s == Status.IDLE else "queued" for s in Status}
# (the kind of the segment so far, a step's kind) where the step goes on in it
# without a wait: the active step is alone in its segment, and the first idle
# step after queued ones waits for its sync
_GOES_ON = frozenset({("queued", "queued"), ("idle", "idle"), ("idle", "queued")})


def segments(course: Course, member: Mapping[str, str]) -> list[Segment]:
    """Cut a course where a wait may come: after the active skill, at the first
    unsynchronized skill, at each barrier skill."""
    out: list[Segment] = []
    for i, step in enumerate(course.steps):
        bid = member.get(step.skill.id)
        kind = _KIND[step.skill.status]
        if not out or bid is not None or (out[-1].kind, kind) not in _GOES_ON:
            if out:
                out[-1].last = i
            out.append(Segment(i, i + 1, kind, bid))
    if out:
        out[-1].last = len(course.steps)
    return out


def halted(mission: Mission, inputs: PlanInputs, robot: str) -> bool:
    """It waits for a run command: its telemetry says so, or its last
    finished skill failed and nothing is active (a failure halts the queue)."""
    now = inputs.robots.get(robot)
    if now is not None and now.mode == "halted":
        return True
    return _failure_halts(mission.tasks.get(robot, []))


def _failure_halts(task: list[SkillInstance]) -> bool:
    """Nothing of `task` is active and its last finished skill failed."""
    if any(s.status in ACTIVE for s in task):
        return False
    last = next((s for s in reversed(task) if s.status in FINISHED), None)
    return last is not None and last.status == Status.FAILURE


class _Clock:
    """The clock pass: lays the segments of every robot, held at barriers."""

    def __init__(self, fc: Forecast, inputs: PlanInputs):
        self.fc = fc
        self.inputs = inputs
        self.arrived: dict[str, dict[str, tuple[float, str | None]]] = {}
        self.cursor: dict[str, float] = {}
        self.prev: dict[str, str | None] = {}

    def run(self) -> None:
        for robot in self.fc.tracks:
            self.cursor[robot] = self.inputs.now
            self.prev[robot] = None
        moved = True
        while moved:
            moved = False
            for robot, track in self.fc.tracks.items():
                while track.laid < len(track.segments):
                    if not self._lay(robot, track, track.segments[track.laid]):
                        break
                    track.laid += 1
                    moved = True

    def _ready(self, robot: str, track: Track, seg: Segment) -> tuple[float, str | None]:
        """When the robot can start the segment, and the skill that decides it."""
        now = self.inputs.now
        earliest = now
        if seg.kind == "idle" or (seg.kind == "queued" and seg.first == 0 and track.halted):
            earliest = self.inputs.link_of(robot).reaches(now)
        t, prev = self.cursor[robot], self.prev[robot]
        if prev is not None and t >= earliest:
            return t, prev
        return max(t, earliest), None

    def _lay(self, robot: str, track: Track, seg: Segment) -> bool:
        """Put one segment on the clock; False when it waits at a barrier."""
        c = track.course
        if seg.kind == "active":
            seg.ready = seg.start = _started(c.steps[seg.first].skill, self.inputs.now)
            seg.end = self._active_end(robot, c.steps[seg.first], seg.start)
        else:
            seg.ready, seg.after = self._ready(robot, track, seg)
            seg.start = seg.ready
            if seg.barrier is not None:
                if seg.barrier in self.fc.barriers.stuck:
                    return False
                if c.steps[seg.first].skill.status == Status.SYNCHWAITING:
                    seg.ready, seg.after = self.inputs.now, None
                arrivals = self.arrived.setdefault(seg.barrier, {})
                arrivals.setdefault(robot, (seg.ready, seg.after))
                if len(arrivals) < len(self.fc.barriers.pending[seg.barrier]):
                    return False
                seg.ready = arrivals[robot][0]
                seg.start, seg.after = max(arrivals.values(), key=lambda v: v[0])
            speed = self.fc.speed
            seg.end = seg.start + (c.offsets[seg.last] - c.offsets[seg.first]) / speed
        self.cursor[robot] = seg.end
        self.prev[robot] = c.steps[seg.last - 1].skill.id
        return True

    def _active_end(self, robot: str, step: Step, start: float) -> float:
        s = step.skill
        now = self.inputs.now
        speed = self.fc.speed
        tele = self.inputs.robots.get(robot)
        if s.status == Status.RUNNING and tele is not None and tele.skill == s.id:
            if tele.eta_s is not None:
                return max(now, tele.at + tele.eta_s / speed)
            return max(now, tele.at + step.busy_s / speed)
        if s.status == Status.PAUSED:  # as if resumed now
            return now + step.busy_s / speed
        return max(now, start + step.busy_s / speed)


def _started(s: SkillInstance, now: float) -> float:
    return s.started_at.timestamp() if s.started_at is not None else now


def _summaries(fc: Forecast) -> None:
    for robot, track in fc.tracks.items():
        fc.robots[robot] = _robot_summary(robot, track)
    fc.end = _mission_end(fc)
    fc.last = _last_skill(fc)


def _robot_summary(robot: str, track: Track) -> RobotForecast:
    """A robot's forecast: its end, or the barrier skill it is held at."""
    c = track.course
    blocked = track.laid < len(track.segments)
    laid = track.segments[: track.laid]
    return RobotForecast(
        robot=robot,
        end=laid[-1].end if laid and not blocked else None,
        blocked_at=c.steps[track.segments[track.laid].first].skill.id if blocked else None,
        battery_end=c.steps[-1].battery_end if c.steps else None,
        battery_assumed=c.battery_assumed,
        halted=track.halted,
    )


def _mission_end(fc: Forecast) -> float | None:
    """When the last robot ends (None: never, one is held at a barrier)."""
    if any(r.blocked_at is not None for r in fc.robots.values()):
        return None
    ends = [(r.end, r.robot) for r in fc.robots.values() if r.end is not None]
    return max(ends)[0] if ends else fc.now


def _last_skill(fc: Forecast) -> str | None:
    """The skill laid on the clock that ends last."""
    last = [(t.segments[t.laid - 1].end, r) for r, t in fc.tracks.items() if t.laid and t.segments]
    if not last:
        return None
    track = fc.tracks[max(last)[1]]
    return track.course.steps[track.segments[track.laid - 1].last - 1].skill.id


class Forecaster:
    """Forecasts of one mission as it changes, reusing what did not change:
    legs per skill, courses per robot, segments per course."""

    def __init__(self, library: Library):
        self.library = library
        self.legs = LegCache()
        self._courses: dict[str, tuple[tuple[SkillInstance, ...], object, Course]] = {}
        self._segments: dict[str, tuple[Course, object, list[Segment]]] = {}

    def course(self, mission: Mission, robot: str, inputs: PlanInputs) -> Course:
        task = mission.tasks.get(robot, [])
        key = (inputs.robots.get(robot), inputs.site_version(), inputs.home_point())
        hit = self._courses.get(robot)
        if hit is not None and hit[1] == key and _same(hit[0], task):
            return hit[2]
        spec = mission.robots.get(robot)
        rtype = spec.type if spec is not None else ""
        course = walk(self.library, robot, rtype, task, inputs, self.legs, mission.markers)
        self._courses[robot] = (tuple(task), key, course)
        return course

    def _track(self, robot: str, course: Course, barriers: BarrierAnalysis) -> list[Segment]:
        member = {barriers.pending[b][robot]: b for b in barriers.sequence.get(robot, [])}
        key = tuple(sorted(member.items()))
        hit = self._segments.get(robot)
        if hit is not None and hit[0] is course and hit[1] == key:
            cut = hit[2]
        else:
            cut = segments(course, member)
            self._segments[robot] = (course, key, cut)
        # fresh copies: the clock writes into them
        return [Segment(s.first, s.last, s.kind, s.barrier) for s in cut]

    def forecast(self, mission: Mission, inputs: PlanInputs) -> Forecast:
        speed = inputs.speed if inputs.speed > 0 else 1.0
        fc = Forecast(now=inputs.now, speed=speed, barriers=analyse(mission))
        for robot in mission.robots:
            course = self.course(mission, robot, inputs)
            fc.tracks[robot] = Track(
                course, self._track(robot, course, fc.barriers), 0, halted(mission, inputs, robot)
            )
        self._forget(mission)
        _Clock(fc, inputs).run()
        _summaries(fc)
        return fc

    def _forget(self, mission: Mission) -> None:
        """Drop what is kept of robots the mission no longer has, and the legs
        of skills it no longer has once they outnumber its skills twice."""
        for gone in [r for r in self._courses if r not in mission.robots]:
            del self._courses[gone]
            self._segments.pop(gone, None)
        if self.legs.size() > 2 * sum(len(t) for t in mission.tasks.values()) + 64:
            self.legs.forget(mission.all_ids())


def _same(old: tuple[SkillInstance, ...], new: list[SkillInstance]) -> bool:
    return len(old) == len(new) and all(a is b for a, b in zip(old, new, strict=True))


def forecast(mission: Mission, library: Library, inputs: PlanInputs) -> Forecast:
    """One forecast from scratch."""
    return Forecaster(library).forecast(mission, inputs)
