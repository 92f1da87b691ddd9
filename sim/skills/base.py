"""The plumbing the skill handlers of a simulated robot share (sim/skills/<family>.py).

Each handler steps its robot through the world in small sim-time steps
(`ctx.sleep(dt)`: honours pause and stop, scaled by the sim speed), drains the
battery with distance and work, reports progress with an ETA in robot (sim)
seconds, and fails with a sentence saying what happened and what to do. Here:
time (`tick`), stationary work, moving along a planned path and climbing,
energy, failing, and the positions and percentages of parameters and messages.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NoReturn

from backend.agent import SkillContext, SkillFailed, Success
from backend.core.model import Pose, Position
from sim.errors import SimError
from sim.ground import StoneReport, StoneSeen
from sim.objects import _fmt
from sim.pathing import SLOW, Follower
from sim.robot import SimRobot
from sim.skills.host import SkillHost
from sim.worldfile import RobotModel

CLIMB_RATE = 1.0  # m/s, drone
RESYNC_S = 120.0  # sim seconds behind the clock past which a robot stops catching up
DRONE_MARGIN_S = 40.0  # flight seconds a drone keeps beyond its way back to the lander
# a drone's explore range: its model's sensor_range at this altitude, in proportion to
# the altitude, within these bounds (m)
DRONE_RANGE_ALTITUDE = 5.0
DRONE_RANGE = (8.0, 40.0)


def drone_range(model: RobotModel, altitude: float) -> float:
    """Metres a drone's camera maps around it at `altitude`."""
    low, high = DRONE_RANGE
    return max(low, min(high, model.sensor_range * max(altitude, 1.0) / DRONE_RANGE_ALTITUDE))


def xy(value: Pose | Position) -> tuple[float, float]:
    """(x, y) of a pose or position parameter (typed by its kind: never a mapping)."""
    return float(value.x), float(value.y)


def pct(x: float) -> str:
    return f"{x * 100:.0f}%"


@dataclass
class MoveLeg:
    """One `move`: the path, what it may spend, what it sees and how it reports."""

    path: Follower
    floor: float  # battery it may not use (the reserve, unless on the way to the lander)
    sense: float  # metres around the robot mapped on the way
    discover: bool  # look for regions ideal for sampling stones on the way
    empty: Callable[[float, float], str] | None  # (done, total) m -> why the battery ran out
    what: str
    frac0: float
    frac1: float


def _leg_over(path: Follower, tolerance: float, stop_when: Callable[[], bool] | None) -> bool:
    """The leg's end is reached (within `tolerance`), or `stop_when()` ends it early."""
    if path.finished or path.remaining <= tolerance:
        return True
    return stop_when is not None and stop_when()


class SkillBase:
    """The plumbing shared by the skill handlers of one simulated robot."""

    rest_eta = 0.0  # sim seconds of the skill after the current phase (for the ETA)

    def __init__(self, host: SkillHost, robot: SimRobot):
        self.host = host
        self.world = host.world
        self.robot = robot
        self._due: float | None = None  # the clock time the current step ends at
        self._ctx: SkillContext | None = None  # the skill run those steps belong to
        self._paused_mark = 0.0  # robot.paused_s when the last step began

    # ------------------------------------------------------------ time, energy, failing

    @property
    def dt(self) -> float:
        """Sim seconds of one step."""
        return self.host.dt

    async def tick(self, ctx: SkillContext, dt: float | None = None) -> float:
        """Let `dt` sim seconds pass (pause/stop aware)."""
        dt = self.dt if dt is None else dt
        await ctx.sleep(self._wait(ctx, dt))
        self.robot.sim_seconds += dt
        self.host.robot_seconds += dt
        return dt

    def _wait(self, ctx: SkillContext, dt: float) -> float:
        """Sim seconds to sleep for a step of `dt`: steps keep to the fleet's clock, so a
        robot that fell behind it (a busy machine) catches up instead of drifting."""
        r, w = self.robot, self.world
        if w.clock_source is None:  # no running clock (a test's host): just wait
            return dt
        now = w.now()
        if self._due is None or self._ctx is not ctx:
            self._due, self._ctx = now, ctx  # a new skill run starts on the clock
        else:
            self._due += r.paused_s - self._paused_mark  # a pause moves the schedule
            if now - self._due > RESYNC_S:
                self._due = now
        self._paused_mark = r.paused_s
        self._due += dt
        return max(0.0, self._due - now)

    def fail(self, reason: str) -> SkillFailed:
        """The failure to raise, its reason kept in the referee's log."""
        self.world.log(f"{self.robot.name}: {reason}")
        return SkillFailed(reason)

    def need_kind(self, *kinds: str, skill: str) -> None:
        if self.robot.kind not in kinds:
            raise self.fail(f"{self.robot.name} is a {self.robot.kind}: it cannot {skill}")

    def dist(self, x: float, y: float) -> float:
        return math.hypot(self.robot.x - x, self.robot.y - y)

    def drain_idle(self, dt: float, load: float = 1.0) -> None:
        """Energy for dt seconds of work (a drone in the air: flight energy)."""
        r = self.robot
        if r.kind == "drone" and r.airborne:
            r.battery -= r.flight_energy(dt)
        else:
            r.battery -= r.work_energy(dt, load)
        r.battery = max(0.0, r.battery)

    async def work(
        self,
        ctx: SkillContext,
        seconds: float,
        what: str,
        *,
        load: float = 1.0,
        frac0: float = 0.0,
        frac1: float = 1.0,
    ) -> None:
        """Stationary work for `seconds` (sim), progress frac0..frac1."""
        r = self.robot
        done = 0.0
        while done < seconds - 1e-9:
            dt = min(self.dt, seconds - done)
            await self.tick(ctx, dt)
            done += dt
            self.drain_idle(dt, load)
            if r.usable <= 0.0:
                self.emergency_landing()
                raise self.fail(
                    f"battery empty while {what} ({pct(r.battery)} left); recharge at the lander"
                )
            frac = frac0 + (frac1 - frac0) * done / seconds
            ctx.progress(frac, what, eta_s=(seconds - done) + self.rest_eta)

    def emergency_landing(self) -> None:
        """A drone in the air with its battery at the reserve comes down where it is."""
        r = self.robot
        if r.kind == "drone" and r.airborne:
            r.airborne = False
            r.z = 0.0
            self.world.log(
                f"{r.name} made an emergency landing at {_fmt(r.x, r.y)}: battery at the reserve"
            )

    # ------------------------------------------------------------ moving

    async def move(
        self,
        ctx: SkillContext,
        goal: tuple[float, float],
        speed: float,
        *,
        tolerance: float = 0.5,
        sense: float = 0.0,
        discover: bool = False,
        allow_reserve: bool = False,
        what: str = "driving",
        frac0: float = 0.0,
        frac1: float = 1.0,
        stop_when: Callable[[], bool] | None = None,
        empty: Callable[[float, float], str] | None = None,
        report: Callable[[], None] | None = None,
        budget: Callable[[], float] | None = None,
    ) -> float:
        """Drive (rover, along the terrain) or fly (drone, straight) to `goal`.
        Returns metres moved. Raises SkillFailed when the battery runs out.

        `stop_when()` ends the leg early, `budget()` caps a step's sim seconds,
        `report()` replaces the progress report, `empty(done, total)` says why
        the battery ran out."""
        if self.dist(*goal) <= tolerance:
            return 0.0
        r = self.robot
        leg = MoveLeg(
            path=Follower(self._route(goal)),
            floor=0.0 if allow_reserve else r.model.reserve,
            sense=sense or r.model.nav_range,
            discover=discover,
            empty=empty,
            what=what,
            frac0=frac0,
            frac1=frac1,
        )
        while not _leg_over(leg.path, tolerance, stop_when):
            if not await self._move_step(ctx, leg, speed, tolerance, budget, report):
                break
        return leg.path.done

    async def _move_step(
        self,
        ctx: SkillContext,
        leg: MoveLeg,
        speed: float,
        tolerance: float,
        budget: Callable[[], float] | None,
        report: Callable[[], None] | None,
    ) -> bool:
        """One step along the leg, reported (False: no time left to move in)."""
        v, per_m = self._pace(speed)
        remaining = max(0.0, leg.path.remaining - tolerance * 0.5)
        step = self._step_time(remaining, v, budget)
        if step <= 1e-6:
            return False
        dt = await self.tick(ctx, step)
        self._advance(leg, min(v * dt, remaining), per_m, self._upkeep(dt))
        if report is not None:
            report()
        else:
            self._report_leg(ctx, leg, v)
        return True

    async def move_before(
        self,
        ctx: SkillContext,
        rest_s: float,
        goal: tuple[float, float],
        speed: float,
        **options: Any,
    ) -> float:
        """`move`, with `rest_s` sim seconds of the skill still to come (for the ETA)."""
        self.rest_eta = rest_s
        try:
            return await self.move(ctx, goal, speed, **options)
        finally:
            self.rest_eta = 0.0

    def _route(self, goal: tuple[float, float]) -> list[tuple[float, float]]:
        try:
            r = self.robot
            return self.world.terrain.route((r.x, r.y), goal, flies=r.kind == "drone")
        except SimError as e:
            raise self.fail(str(e)) from None

    def _pace(self, speed: float) -> tuple[float, float]:
        """Speed here (m/s) and energy per metre: a rover slows on slow ground and pays
        by the metre; a drone flies at `speed` and pays by the second (`_upkeep`)."""
        r, w = self.robot, self.world
        if r.kind == "drone":
            return speed, 0.0
        slow = w.terrain.at(r.x, r.y) == SLOW
        v = speed * (w.spec.terrain.slow_factor if slow else 1.0)
        return v, r.drive_energy(1.0, w.spec.terrain.slow_energy if slow else 1.0)

    def _step_time(self, remaining: float, v: float, budget: Callable[[], float] | None) -> float:
        # the last step of a leg takes only the time it needs
        step = min(self.dt, remaining / max(v, 1e-6))
        if budget is not None:  # end exactly on a time budget, whatever the step
            step = min(step, budget())
        return step

    def _upkeep(self, dt: float) -> float:
        """Energy a moving robot spends by the second (a drone: all of its flight)."""
        r = self.robot
        return r.flight_energy(dt) if r.kind == "drone" else r.work_energy(dt)

    def _advance(self, leg: MoveLeg, want: float, per_m: float, fixed: float) -> None:
        """One step of `want` metres, unless the battery runs out on the way."""
        r = self.robot
        if want * per_m + fixed > r.battery - leg.floor:
            self._run_dry(leg, want, per_m, fixed)
        moved = leg.path.advance(want)
        r.battery = max(0.0, r.battery - moved * per_m - fixed)
        self._moved(leg, moved)

    def _run_dry(self, leg: MoveLeg, want: float, per_m: float, fixed: float) -> NoReturn:
        """The battery runs out during this step: go as far as the energy allows, stop."""
        r, path = self.robot, leg.path
        spare = r.battery - leg.floor
        if per_m > 0:
            can = max(0.0, (spare - fixed) / per_m)
        else:
            can = want * max(0.0, spare) / fixed if fixed > 0 else want
        self._moved(leg, path.advance(min(can, want)))
        r.battery = leg.floor
        self.emergency_landing()
        if leg.empty is not None:
            raise self.fail(leg.empty(path.done, path.total))
        kept = " (the reserve is kept to reach the lander)" if leg.floor > 0 else ""
        raise self.fail(
            f"battery empty after {path.done:.0f} m of {path.total:.0f} m{kept}; "
            "recharge at the lander"
        )

    def _moved(self, leg: MoveLeg, moved: float) -> None:
        r, path = self.robot, leg.path
        r.x, r.y = path.x, path.y
        if moved > 0:
            r.yaw = path.heading
            r.odometer += moved
        self.world.reveal(r, leg.sense)
        if self.world.in_range(r):
            self.world.downlink.crossed_coverage(r)  # its news goes out at the next pump
        if leg.discover:
            for name in self.world.discover(r, leg.sense):
                self.host.note(r, f"found {name}")

    def _report_leg(self, ctx: SkillContext, leg: MoveLeg, v: float) -> None:
        path = leg.path
        total = path.total
        frac = leg.frac0 + (leg.frac1 - leg.frac0) * (path.done / total if total > 0 else 1.0)
        eta = path.remaining / max(v, 1e-6) + self.rest_eta
        ctx.progress(frac, f"{leg.what}: {path.done:.0f} of {total:.0f} m", eta_s=eta)

    # ------------------------------------------------------------ shared by families

    def check_speed(self, speed: float) -> float:
        m = self.robot.model
        if speed <= 0:
            raise self.fail("the speed must be positive")
        return min(speed, m.max_speed)

    def sensor_range(self) -> float:
        r = self.robot
        if r.kind == "drone":
            return drone_range(r.model, r.z)
        return r.model.sensor_range

    def learn_stone(self, info: dict[str, Any]) -> None:
        """The robot saw the stone (the truth, so the newest): it knows it and reports it."""
        self.robot.knowledge.learn_stone(info)
        self.world.tell_ground(self.robot, StoneSeen(StoneReport.of(info)))

    def done(self, ctx: SkillContext, text: str) -> Success:
        """The skill's result: kept for the status, reported as its outcome."""
        self.host.note(self.robot, text)
        ctx.progress(1.0, text, eta_s=0.0)
        return Success(text)

    # ------------------------------------------------------------ drone flight

    async def climb(
        self, ctx: SkillContext, altitude: float, frac0: float = 0.0, frac1: float = 1.0
    ) -> None:
        r = self.robot
        seconds = abs(altitude - r.z) / CLIMB_RATE + 5.0
        z0 = r.z
        done = 0.0
        while done < seconds - 1e-9:
            dt = min(self.dt, seconds - done)
            await self.tick(ctx, dt)
            done += dt
            r.battery = max(0.0, r.battery - r.flight_energy(dt))
            r.z = z0 + (altitude - z0) * min(1.0, done / seconds)
            ctx.progress(
                frac0 + (frac1 - frac0) * done / seconds,
                f"altitude {r.z:.1f} m",
                eta_s=seconds - done,
            )
        r.z = altitude

    def grounded_away(self) -> SkillFailed:
        """A drone on the ground away from the pad: it must take off to get anywhere."""
        r = self.robot
        d = self.world.dist_to_lander(r.x, r.y)
        return self.fail(f"{r.name} is on the ground {d:.0f} m from the lander pad: take off first")

    async def descend(self, ctx: SkillContext, frac0: float = 0.0, frac1: float = 1.0) -> None:
        r = self.robot
        await self.climb(ctx, 0.0, frac0, frac1)
        r.airborne = False
        r.z = 0.0

    async def fly_home(self, ctx: SkillContext, frac0: float = 0.0, frac1: float = 1.0) -> None:
        r, w = self.robot, self.world

        def empty(done: float, total: float) -> str:
            return (
                f"battery at the reserve after {done:.0f} m of {total:.0f} m back to the lander: "
                f"{r.name} made an emergency landing at {_fmt(r.x, r.y)}"
            )

        await self.move(
            ctx,
            (w.spec.lander.x, w.spec.lander.y),
            r.model.speed,
            tolerance=0.3,
            allow_reserve=True,
            what="flying to the lander pad",
            frac0=frac0,
            frac1=frac1,
            empty=empty,
        )
