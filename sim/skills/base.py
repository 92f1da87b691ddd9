"""Skill handlers of the simulated robots (every skill of missions/libraries/mars.yaml).

Each handler steps its robot through the world in small sim-time steps
(`ctx.sleep(dt)`: honours pause and stop, scaled by the sim speed), drains the
battery with distance and work, reports progress with an ETA in robot (sim)
seconds, and fails with a sentence saying what happened and what to do.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from backend.agent import SkillContext, SkillFailed
from sim.pathing import SLOW, Follower
from sim.skills.host import SkillHost
from sim.world import SimError, SimRobot, _fmt

CLIMB_RATE = 1.0  # m/s, drone


def _xy(value: Any) -> tuple[float, float]:
    """(x, y) of a Pose, Position or mapping."""
    if value is None:
        raise SkillFailed("a position parameter is missing")
    if isinstance(value, dict):
        return float(value.get("x", 0.0)), float(value.get("y", 0.0))
    return float(value.x), float(value.y)


def _yaw(value: Any) -> float | None:
    if isinstance(value, dict):
        return float(value["yaw"]) if "yaw" in value else None
    return float(getattr(value, "yaw", 0.0)) if hasattr(value, "yaw") else None


def _pct(x: float) -> str:
    return f"{x * 100:.0f}%"


class SkillBase:
    """The plumbing shared by the skill handlers of one simulated robot."""

    def __init__(self, host: SkillHost, robot: SimRobot):
        self.host = host
        self.world = host.world
        self.robot = robot

    @property
    def dt(self) -> float:
        return self.host.dt

    async def tick(self, ctx: SkillContext, dt: float | None = None) -> float:
        """Let `dt` sim seconds pass (pause/stop aware)."""
        dt = self.dt if dt is None else dt
        await ctx.sleep(dt)
        self.robot.sim_seconds += dt
        self.host.robot_seconds += dt
        return dt

    def fail(self, reason: str) -> SkillFailed:
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
            r.battery -= self.world.flight_energy(r, dt)
        else:
            r.battery -= self.world.work_energy(r, dt, load)
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
        until: Callable[[], bool] | None = None,
    ) -> None:
        """Stationary work for `seconds` (sim), progress frac0..frac1. `until()` ends it early."""
        r = self.robot
        done = 0.0
        while done < seconds - 1e-9:
            if until is not None and until():
                return
            dt = min(self.dt, seconds - done)
            await self.tick(ctx, dt)
            done += dt
            self.drain_idle(dt, load)
            if r.usable <= 0.0:
                self.emergency_landing()
                raise self.fail(
                    f"battery empty while {what} ({_pct(r.battery)} left); recharge at the lander"
                )
            frac = frac0 + (frac1 - frac0) * done / seconds
            ctx.progress(frac, what, eta_s=(seconds - done) + self.rest_eta)
        if until is not None:
            until()

    rest_eta = 0.0  # sim seconds of the skill after the current phase (for the ETA)

    def emergency_landing(self) -> None:
        r = self.robot
        if r.kind == "drone" and r.airborne:
            r.airborne = False
            r.z = 0.0
            self.world.log(
                f"{r.name} made an emergency landing at {_fmt(r.x, r.y)}: battery at the reserve"
            )

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
        Returns metres moved. Raises SkillFailed when the battery runs out."""
        r, w = self.robot, self.world
        if self.dist(*goal) <= tolerance:
            return 0.0
        try:
            route = w.plan_route(r, goal)
        except SimError as e:
            raise self.fail(str(e)) from None
        f = Follower(route)
        total = f.total
        floor = 0.0 if allow_reserve else r.model.reserve
        slow_factor = w.spec.terrain.slow_factor
        sense = sense or r.model.nav_range
        while not f.finished and f.remaining > tolerance:
            if stop_when is not None and stop_when():
                break
            if r.kind == "drone":
                v = speed
                per_m = 0.0
            else:
                code = w.terrain_at(r.x, r.y)
                v = speed * (slow_factor if code == SLOW else 1.0)
                per_m = w.drive_energy(r, 1.0, code)
            remaining = max(0.0, f.remaining - tolerance * 0.5)
            # the last step of a leg takes only the time it needs
            step = min(self.dt, remaining / max(v, 1e-6))
            if budget is not None:  # end exactly on a time budget, whatever the step
                step = min(step, budget())
            if step <= 1e-6:
                break
            dt = await self.tick(ctx, step)
            fixed = w.flight_energy(r, dt) if r.kind == "drone" else w.work_energy(r, dt)
            want = min(v * dt, remaining)
            spare = r.battery - floor
            if want * per_m + fixed > spare:
                # runs out during this step: go as far as the energy allows
                if per_m > 0:
                    can = max(0.0, (spare - fixed) / per_m)
                else:
                    can = want * max(0.0, spare) / fixed if fixed > 0 else want
                moved = f.advance(min(can, want))
                self._moved(f, moved, sense, discover)
                r.battery = floor
                self.emergency_landing()
                if empty is not None:
                    raise self.fail(empty(f.done, total))
                raise self.fail(
                    f"battery empty after {f.done:.0f} m of {total:.0f} m"
                    f"{' (the reserve is kept to reach the lander)' if floor > 0 else ''}; recharge at the lander"
                )
            moved = f.advance(want)
            r.battery = max(0.0, r.battery - moved * per_m - fixed)
            self._moved(f, moved, sense, discover)
            if report is not None:
                report()
                continue
            frac = frac0 + (frac1 - frac0) * (f.done / total if total > 0 else 1.0)
            eta = f.remaining / max(v, 1e-6) + self.rest_eta
            ctx.progress(frac, f"{what}: {f.done:.0f} of {total:.0f} m", eta_s=eta)
        return f.done

    def _moved(self, f: Follower, moved: float, sense: float, discover: bool) -> None:
        r = self.robot
        r.x, r.y = f.x, f.y
        if moved > 0:
            r.yaw = f.heading
            r.odometer += moved
        self.world.reveal(r, sense)
        if discover:
            for name in self.world.discover(r, sense):
                self.host.note(r, f"found {name}")

    def check_speed(self, speed: float) -> float:
        m = self.robot.model
        if speed <= 0:
            raise self.fail("the speed must be positive")
        return min(speed, m.max_speed)

    def sensor_range(self) -> float:
        r = self.robot
        if r.kind == "drone":
            return max(8.0, min(40.0, r.model.sensor_range * max(r.z, 1.0) / 5.0))
        return r.model.sensor_range

    def _learn_stone(self, info: dict[str, Any]) -> None:
        self.robot.knowledge.stones[info["id"]] = dict(info)
        self.world.tell_ground(self.robot, "stone", info["id"], info)

    async def _climb(
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
            r.battery = max(0.0, r.battery - self.world.flight_energy(r, dt))
            r.z = z0 + (altitude - z0) * min(1.0, done / seconds)
            ctx.progress(
                frac0 + (frac1 - frac0) * done / seconds,
                f"altitude {r.z:.1f} m",
                eta_s=seconds - done,
            )
        r.z = altitude

    async def _descend(self, ctx: SkillContext, frac0: float = 0.0, frac1: float = 1.0) -> None:
        r = self.robot
        await self._climb(ctx, 0.0, frac0, frac1)
        r.airborne = False
        r.z = 0.0

    async def _fly_home(self, ctx: SkillContext, frac0: float = 0.0, frac1: float = 1.0) -> None:
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
