"""takeoff, fly_to and land: the drone's flight."""

from __future__ import annotations

from backend.agent import SkillContext, Success
from backend.core.model import Pose
from sim.objects import _fmt
from sim.skills.base import CLIMB_RATE, DRONE_MARGIN_S, SkillBase, pct, xy

MIN_TAKEOFF = 0.05  # battery above the reserve a drone needs to take off


class AerialSkills(SkillBase):
    """takeoff, fly_to and land handlers."""

    def _need_drone(self, skill: str) -> None:
        if self.robot.kind != "drone":
            raise self.fail(f"{self.robot.name} cannot {skill}: it is not a drone")

    async def takeoff(self, ctx: SkillContext, altitude: float) -> Success:
        self._need_drone("take off")
        r = self.robot
        if not r.airborne and r.usable < MIN_TAKEOFF:
            raise self.fail(
                f"battery {pct(r.battery)} is too low to take off "
                f"(reserve {pct(r.model.reserve)}); recharge first"
            )
        r.airborne = True
        await self.climb(ctx, float(altitude))
        return self.done(ctx, f"hovering at {r.z:.0f} m, battery {pct(r.battery)}")

    async def fly_to(self, ctx: SkillContext, goal: Pose, altitude: float, speed: float) -> Success:
        self._need_drone("fly")
        r = self.robot
        if not r.airborne:
            raise self.fail(f"{r.name} is on the ground: take off first")
        gx, gy = xy(goal)
        speed = self.check_speed(speed)
        self._check_range(gx, gy, altitude, speed)
        if abs(altitude - r.z) > 0.1:
            await self.climb(ctx, float(altitude), frac1=0.05)
        await self.move(
            ctx,
            (gx, gy),
            speed,
            tolerance=0.3,
            what=f"flying to {_fmt(gx, gy)}",
            frac0=0.05,
            sense=max(r.model.nav_range, self.sensor_range() * 0.5),
            empty=self._landed_short,
        )
        r.yaw = goal.yaw
        return self.done(ctx, f"hovering at {_fmt(r.x, r.y)}, battery {pct(r.battery)}")

    def _check_range(self, gx: float, gy: float, altitude: float, speed: float) -> None:
        """Refuse a flight the battery cannot do there and back to the lander."""
        r = self.robot
        d = self.dist(gx, gy)
        back = self.world.dist_to_lander(gx, gy)
        need_s = (
            d / speed + abs(altitude - r.z) / CLIMB_RATE + back / r.model.speed + DRONE_MARGIN_S
        )
        need = need_s / r.model.flight_s_per_battery
        if need > r.usable:
            reach = r.usable * r.model.flight_s_per_battery * speed
            raise self.fail(
                f"{r.name} cannot fly {d:.0f} m to {_fmt(gx, gy)} and back to the lander "
                f"({back:.0f} m): needs {pct(need)} of a battery, has {pct(r.usable)} above "
                f"the {pct(r.model.reserve)} reserve (about {reach:.0f} m); refused before "
                "the flight: land on the lander pad to recharge"
            )

    def _landed_short(self, done: float, total: float) -> str:
        r = self.robot
        return (
            f"battery at the reserve after {done:.0f} m of {total:.0f} m: "
            f"{r.name} made an emergency landing at {_fmt(r.x, r.y)}"
        )

    async def land(self, ctx: SkillContext, where: str) -> Success:
        self._need_drone("land")
        r, w = self.robot, self.world
        if not r.airborne:
            if where == "here" or w.at_lander(r):
                return self.done(ctx, "already on the ground")
            raise self.grounded_away()
        if where == "lander_pad":
            await self.fly_home(ctx, frac1=0.7)
            await self.descend(ctx, frac0=0.7)
            msg = f"landed on the lander pad: charging from {pct(r.battery)}"
        else:
            await self.descend(ctx)
            msg = f"landed at {_fmt(r.x, r.y)}"
        return self.done(ctx, msg)
