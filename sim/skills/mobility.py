"""drive_to and explore: rovers drive, rovers and drones map an area."""

from __future__ import annotations

from typing import Any

import numpy as np

from backend.agent import SkillContext, SkillFailed
from sim.pathing import ROCK, lawnmower
from sim.skills.base import SkillBase, _pct, _xy, _yaw
from sim.world import _fmt


class MobilitySkills(SkillBase):
    """drive_to and explore handlers."""

    async def drive_to(
        self,
        ctx: SkillContext,
        goal: Any = None,
        speed: float = 0.5,
        tolerance: float = 0.5,
        **_: Any,
    ) -> None:
        self.need_kind("rover", skill="drive")
        r = self.robot
        gx, gy = _xy(goal)
        speed = self.check_speed(speed)
        await self.move(
            ctx, (gx, gy), speed, tolerance=tolerance, what=f"driving to {_fmt(gx, gy)}"
        )
        yaw = _yaw(goal)
        if yaw is not None and self.dist(gx, gy) <= max(tolerance, 1.0):
            r.yaw = yaw
        ctx.progress(1.0, f"at {_fmt(r.x, r.y)}", eta_s=0.0)

    async def explore(
        self,
        ctx: SkillContext,
        area: Any = None,
        max_duration: float = 300.0,
        return_to_start: bool = False,
        sensors: Any = None,
        **_: Any,
    ) -> None:
        r, w = self.robot, self.world
        self.need_kind("rover", "drone", skill="explore")
        if r.kind == "drone" and not r.airborne:
            raise self.fail(f"{r.name} is on the ground: take off first")
        if not isinstance(area, list) or len(area) < 3:
            raise self.fail("the area needs at least three corners")
        poly = [_xy(p) for p in area]
        known = set(r.model.capabilities) | {"stereo_camera"}
        for s in sensors or []:
            if str(s) not in known:
                raise self.fail(
                    f"{r.name} has no sensor '{s}' (it has: {', '.join(sorted(known))})"
                )
        rng = self.sensor_range()
        full = w.geom.polygon_mask(poly)
        if r.kind != "drone":
            full &= w.terrain != ROCK
        if not full.any():
            raise self.fail(
                "the area holds no cell this robot can map (too small, or all impassable)"
            )
        rows_i, cols_j = np.nonzero(full)
        win = (
            slice(int(rows_i.min()), int(rows_i.max()) + 1),
            slice(int(cols_j.min()), int(cols_j.max()) + 1),
        )
        mask = full[win]
        cells = int(mask.sum())
        cache = [-1.0, 0.0]  # sim seconds when computed, fraction
        start = (r.x, r.y)
        speed = r.model.speed
        lanes = lawnmower(poly, spacing=1.6 * rng, start=start)
        t0 = r.sim_seconds
        found_before = len(r.knowledge.rss)

        def elapsed() -> float:
            return r.sim_seconds - t0

        def frac() -> float:
            if cache[0] != r.sim_seconds:  # once per step
                cache[0] = r.sim_seconds
                cache[1] = float((w.explored[win] & mask).sum()) / cells
            return cache[1]

        def back_time() -> float:
            return self.dist(*start) / speed if return_to_start else 0.0

        def out_of_time() -> bool:
            return elapsed() + back_time() >= max_duration

        def drone_must_return() -> bool:
            if r.kind != "drone":
                return False
            need = (
                w.dist_to_lander(r.x, r.y) / r.model.speed + 40.0
            ) / r.model.flight_s_per_battery
            return r.usable <= need

        def report() -> None:
            f = frac()
            ctx.progress(
                min(0.99, max(elapsed() / max_duration, f)),
                f"exploring: {_pct(f)} mapped",
                eta_s=max(0.0, max_duration - elapsed()),
            )

        reason_low = ""
        w.reveal(r, rng)
        for name in w.discover(r, rng):
            self.host.note(r, f"found {name}")
        for wp in lanes:
            if frac() >= 0.995 or out_of_time():
                break
            if drone_must_return():
                reason_low = "battery"
                break
            target = wp if r.kind == "drone" else w.nearest_free(*wp, max_r=rng)
            if target is None:
                continue

            def stop_when() -> bool:
                return frac() >= 0.995 or out_of_time() or drone_must_return()

            try:
                await self.move(
                    ctx,
                    target,
                    speed,
                    tolerance=1.0,
                    sense=rng,
                    discover=True,
                    what="exploring",
                    stop_when=stop_when,
                    report=report,
                    budget=lambda: max_duration - elapsed() - back_time(),
                )
            except SkillFailed:
                if r.usable <= 0:
                    raise
                continue  # an unreachable lane end: go on with the next
        if drone_must_return():
            reason_low = "battery"
        if return_to_start and self.dist(*start) > 1.0:
            await self.move(
                ctx, start, speed, tolerance=1.0, sense=rng, discover=True, what="returning"
            )
        found = list(r.knowledge.rss)[found_before:]
        summary = f"explored {_pct(frac())} of the area in {elapsed():.0f} s"
        summary += (
            f"; found {', '.join(found)}" if found else "; no new region ideal for sampling stones"
        )
        if reason_low:
            raise self.fail(
                f"stopped exploring: {summary}; {r.name} needs its remaining {_pct(r.battery)} battery "
                "to fly back to the lander"
            )
        self.host.note(r, summary)
        ctx.progress(1.0, summary, eta_s=0.0)
