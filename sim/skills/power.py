"""recharge: back to the lander and charge."""

from __future__ import annotations

from backend.agent import SkillContext, Success
from sim.skills.base import SkillBase, pct

PAD_INSIDE = 1.5  # metres inside the pad's edge a rover parks to charge


class PowerSkills(SkillBase):
    """recharge handlers."""

    async def recharge(self, ctx: SkillContext, target_level: float) -> Success:
        r, w = self.robot, self.world
        self.need_kind("rover", "drone", skill="recharge")
        target_level = min(1.0, max(0.0, float(target_level)))
        if r.kind == "drone":
            if not w.docked(r):
                await self._fly_to_pad(ctx)
        elif not w.at_lander(r):
            await self._drive_to_lander(ctx)
        await self._charge(ctx, target_level)
        return self.done(ctx, f"recharged: battery {pct(r.battery)}")

    async def _fly_to_pad(self, ctx: SkillContext) -> None:
        if not self.robot.airborne:
            raise self.grounded_away()
        await self.fly_home(ctx, frac1=0.3)
        await self.descend(ctx, frac0=0.3, frac1=0.35)

    async def _drive_to_lander(self, ctx: SkillContext) -> None:
        """Onto the pad on the robot's side, using the reserve if it must."""
        r, w = self.robot, self.world
        d = w.dist_to_lander(r.x, r.y)
        lx, ly = w.spec.lander.x, w.spec.lander.y
        k = max(0.0, (w.spec.lander.pad_radius - PAD_INSIDE) / d)
        goal = (lx + (r.x - lx) * k, ly + (r.y - ly) * k)
        free = w.terrain.nearest_free(*goal, max_r=w.spec.lander.pad_radius) or goal
        await self.move(
            ctx,
            free,
            r.model.speed,
            tolerance=0.5,
            allow_reserve=True,
            what="returning to the lander",
            frac1=0.3,
            empty=self._stranded,
        )

    def _stranded(self, done: float, total: float) -> str:
        r = self.robot
        left = self.world.dist_to_lander(r.x, r.y)
        return (
            f"battery empty {left:.0f} m from the lander (drove {done:.0f} of {total:.0f} m): "
            f"{r.name} is stranded"
        )

    async def _charge(self, ctx: SkillContext, target_level: float) -> None:
        r = self.robot
        start = r.battery
        while r.battery < target_level - 1e-9:
            dt = await self.tick(ctx)
            r.charge(dt, up_to=target_level)
            span = max(target_level - start, 1e-9)
            rate = r.model.charge_per_minute / 60.0
            ctx.progress(
                0.35 + 0.65 * (r.battery - start) / span,
                f"charging: {pct(r.battery)}",
                eta_s=(target_level - r.battery) / rate,
            )
