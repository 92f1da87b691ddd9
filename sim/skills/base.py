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

import numpy as np

from backend.agent import SkillContext, SkillFailed, Success
from sim.pathing import ROCK, SLOW, Follower, lawnmower
from sim.skills.host import SkillHost
from sim.world import SimError, SimRobot, Stone, _fmt

CLIMB_RATE = 1.0  # m/s, drone
NEAR_TARGET = 5.0  # extra metres around a search radius that count as "at the target"
APPROACH = 8.0  # a stone/box this close is approached within the skill
CAMERA_RANGE = 15.0  # science camera
PARTNER_WAIT = 300.0  # sim seconds one identifier waits for the other
ASK_PERIOD = 10.0  # sim seconds between asks while waiting for the partner


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


class RobotSkills:
    """The handlers of one simulated robot."""

    def __init__(self, host: SkillHost, robot: SimRobot):
        self.host = host
        self.world = host.world
        self.robot = robot

    # ------------------------------------------------------------ plumbing

    def handlers(self) -> dict[str, Callable[..., Any]]:
        return {
            "drive_to": self.drive_to,
            "explore": self.explore,
            "take_science_image": self.take_science_image,
            "identify_stone": self.identify_stone,
            "pick_stone": self.pick_stone,
            "drop_stone": self.drop_stone,
            "pick_payload_box": self.pick_payload_box,
            "place_payload_box": self.place_payload_box,
            "deploy_wifi_box": self.deploy_wifi_box,
            "recharge": self.recharge,
            "takeoff": self.takeoff,
            "fly_to": self.fly_to,
            "land": self.land,
            "load_box": self.load_box,
        }

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

    # ------------------------------------------------------------ drive_to

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

    # ------------------------------------------------------------ explore

    def sensor_range(self) -> float:
        r = self.robot
        if r.kind == "drone":
            return max(8.0, min(40.0, r.model.sensor_range * max(r.z, 1.0) / 5.0))
        return r.model.sensor_range

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

    # ------------------------------------------------------------ science

    async def take_science_image(
        self,
        ctx: SkillContext,
        target: Any = None,
        filter: str = "multispectral",
        camera: Any = None,
        **_: Any,
    ) -> Success:
        r, w = self.robot, self.world
        if not r.has("science_camera"):
            raise self.fail(f"{r.name} has no science camera")
        tx, ty = _xy(target)
        d = self.dist(tx, ty)
        if d > CAMERA_RANGE:
            raise self.fail(
                f"the target {_fmt(tx, ty)} is {d:.0f} m away; the science camera sees {CAMERA_RANGE:.0f} m: drive closer"
            )
        if r.kind == "rover":
            r.yaw = math.atan2(ty - r.y, tx - r.x) if d > 0.1 else r.yaw
        await self.work(ctx, 60.0, f"imaging {_fmt(tx, ty)} ({filter})", load=1.5)
        rss = w.rss_near(tx, ty, 3.0)
        if rss is None:
            msg = f"no region ideal for sampling stones at {_fmt(tx, ty)}"
        else:
            info = r.knowledge.rss.get(rss.name) or {
                "rss": rss.name,
                "x": rss.x,
                "y": rss.y,
                "radius": rss.radius,
            }
            if r.name not in rss.found_by:
                rss.found_by.add(r.name)
                w.log(f"{r.name} discovered {rss.name} at {_fmt(rss.x, rss.y)}")
            if filter == "visible":
                info.setdefault("top_score", None)
                msg = f"{rss.name}: the visible filter cannot tell stone types; use multispectral"
            else:
                info["top_score"] = rss.max_score
                msg = f"{rss.name}: top stone score {rss.max_score:g}"
                w.log(f"{r.name} imaged {rss.name}: top stone score {rss.max_score:g}")
            r.knowledge.rss[rss.name] = info
            w.tell_ground(r, "rss", rss.name, info)
        self.host.note(r, msg)
        ctx.progress(1.0, msg, eta_s=0.0)
        return Success(msg)

    # ------------------------------------------------------------ stones

    def _near_target(self, tx: float, ty: float, radius: float, what: str) -> None:
        d = self.dist(tx, ty)
        if d > radius + NEAR_TARGET:
            raise self.fail(
                f"{self.robot.name} is {d:.0f} m from the {what} {_fmt(tx, ty)}: drive there first "
                f"(within {radius + NEAR_TARGET:.0f} m)"
            )

    def _collaborating(self, partner: str | None, tx: float, ty: float, need: str) -> bool:
        if not partner:
            return False
        other = self.world.robots.get(partner)
        if other is None or not other.has(need) or other.activity != "identify_stone":
            return False
        rng = self.world.spec.scoring.collab_range
        return math.hypot(other.x - tx, other.y - ty) <= rng and self.dist(tx, ty) <= rng

    def _identify(
        self, rss_name: str, tx: float, ty: float, score: float, by: tuple[str, ...]
    ) -> Stone:
        w = self.world
        hidden = [w.stones[s] for s in w.rss[rss_name].stones if w.stones[s].state == "hidden"]
        if not hidden:
            raise self.fail(f"every stone of {rss_name} is identified already: try another region")
        stone = min(hidden, key=lambda s: (math.hypot(s.x - tx, s.y - ty), s.id))
        stone.score = score
        stone.state = "identified"
        stone.identified_by = by
        self._learn_stone(stone.public())
        w.log(f"{' and '.join(by)} identified {stone.id} in {rss_name} (score {score:g})")
        return stone

    def _learn_stone(self, info: dict[str, Any]) -> None:
        self.robot.knowledge.stones[info["id"]] = dict(info)
        self.world.tell_ground(self.robot, "stone", info["id"], info)

    async def identify_stone(
        self,
        ctx: SkillContext,
        target: Any = None,
        search_radius: float = 3.0,
        partner: str | None = None,
        **_: Any,
    ) -> Success:
        r, w = self.robot, self.world
        tx, ty = _xy(target)
        duration = 120.0
        f0 = 0.0
        if self.dist(tx, ty) > search_radius + NEAR_TARGET:
            # go to the search centre first (part of the skill)
            if r.kind != "rover":
                self._near_target(tx, ty, search_radius, "search centre")
            self.rest_eta = duration
            try:
                await self.move(
                    ctx,
                    (tx, ty),
                    r.model.speed,
                    tolerance=max(1.0, search_radius * 0.5),
                    what="going to the search centre",
                    frac1=0.3,
                )
            finally:
                self.rest_eta = 0.0
            f0 = 0.3
        rss = w.rss_near(tx, ty, search_radius)
        if rss is None:
            await self.work(ctx, duration * 0.3, "searching for stones", frac0=f0)
            raise self.fail(
                f"no region ideal for sampling stones within {search_radius:g} m of {_fmt(tx, ty)}: nothing to identify here"
            )
        if r.name not in rss.found_by:
            rss.found_by.add(r.name)
            info = {
                "rss": rss.name,
                "x": rss.x,
                "y": rss.y,
                "radius": rss.radius,
                "top_score": (r.knowledge.rss.get(rss.name) or {}).get("top_score"),
            }
            r.knowledge.rss[rss.name] = info
            w.tell_ground(r, "rss", rss.name, info)
            w.log(f"{r.name} discovered {rss.name} at {_fmt(rss.x, rss.y)}")
        min_score = w.spec.scoring.min_score
        other = w.robots.get(partner) if partner else None
        span = 1.0 - f0

        def at(frac: float) -> float:
            return f0 + span * frac

        if r.has("science_camera"):
            # The science camera picks the stone; with the manipulator next to it, the best one.
            await self.work(
                ctx,
                duration * 0.8,
                "identifying stones (science camera)",
                frac0=at(0),
                frac1=at(0.8),
            )
            waited = 0.0
            while (
                other is not None
                and other.has("manipulator")
                and other.activity == "identify_stone"
                and not self._collaborating(partner, tx, ty, "manipulator")
                and waited < PARTNER_WAIT
            ):
                await self.work(
                    ctx,
                    self.dt,
                    f"waiting for {partner} to reach the search centre",
                    frac0=at(0.8),
                    frac1=at(0.8),
                )
                waited += self.dt
            collab = self._collaborating(partner, tx, ty, "manipulator")
            stone = self._identify(
                rss.name,
                tx,
                ty,
                rss.max_score if collab else min_score,
                (r.name, partner) if collab and partner else (r.name,),
            )
            await self.work(
                ctx,
                duration * 0.2,
                "identifying stones (science camera)",
                frac0=at(0.8),
                frac1=at(1.0),
            )
            how = (
                f"with {partner}"
                if collab
                else "alone (only a low-score stone without the manipulator)"
            )
        elif other is not None and other.has("science_camera"):
            # LRU2 asks LRU1 which stone it identified (polling while LRU1 works on it)
            await self.work(
                ctx,
                duration * 0.85,
                f"identifying stones with {partner}",
                frac0=at(0),
                frac1=at(0.85),
            )
            answer: dict[str, Any] | None = None
            waited = 0.0
            while True:
                answer = await self.host.ask(
                    r, other.name, "stone", {"x": tx, "y": ty, "radius": search_radius + rss.radius}
                )
                if answer is not None and answer.get("state") == "identified":
                    break
                answer = None
                busy = other.activity == "identify_stone"
                if waited >= (PARTNER_WAIT if busy else duration * 0.15):
                    break
                step = min(ASK_PERIOD, PARTNER_WAIT - waited)
                await self.work(
                    ctx,
                    step,
                    f"waiting for {partner} to point out the stone",
                    frac0=at(0.85),
                    frac1=at(0.85),
                )
                waited += step
            if answer is not None:
                self._learn_stone(answer)
                stone = w.stones[answer["id"]]
                if r.name not in stone.identified_by:
                    stone.identified_by = (*stone.identified_by, r.name)
                how = f"with {partner}: it told where the stone lies"
            else:
                stone = self._identify(rss.name, tx, ty, min_score, (r.name,))
                how = f"alone ({partner} did not point out a stone)"
            await self.work(
                ctx, duration * 0.15, "locating the stone", frac0=at(0.85), frac1=at(1.0)
            )
        else:
            await self.work(ctx, duration, "identifying stones", frac0=at(0), frac1=at(1.0))
            stone = self._identify(rss.name, tx, ty, min_score, (r.name,))
            how = "alone (only a low-score stone without LRU1 and LRU2 together)"
        msg = f"identified {stone.id} at {_fmt(stone.x, stone.y)}, score {stone.score:g}, {how}"
        self.host.note(r, msg)
        ctx.progress(1.0, msg, eta_s=0.0)
        return Success(msg)

    def _capacity(self) -> int:
        r = self.robot
        if r.box is not None and self.world.boxes[r.box].kind == "sample":
            return r.model.carry_stones_in_box
        return r.model.carry_stones

    async def pick_stone(
        self, ctx: SkillContext, target: Any = None, region: str | None = None, **_: Any
    ) -> None:
        r, w = self.robot, self.world
        if not r.has("manipulator"):
            raise self.fail(f"{r.name} has no arm to pick stones")
        tx, ty = _xy(target)
        cap = self._capacity()
        if len(r.stones) >= cap:
            raise self.fail(
                f"{r.name} already carries {len(r.stones)} stone(s) (capacity {cap}"
                f"{'' if r.box else '; carry a sample box for more'}): drop first"
            )
        radius = 6.0

        def known() -> dict[str, Any] | None:
            cands = [
                s
                for s in r.knowledge.stones.values()
                if s.get("state") in ("identified", "ground")
                and math.hypot(s["x"] - tx, s["y"] - ty) <= radius
            ]
            if region:
                cands = [s for s in cands if s.get("rss") == region] or cands
            return min(
                cands,
                key=lambda s: (-(s.get("score") or 0), math.hypot(s["x"] - tx, s["y"] - ty)),
                default=None,
            )

        info = known()
        asked: list[str] = []
        if info is None:
            order = sorted(
                (o for o in w.robots.values() if o.name != r.name and o.kind != "static"),
                key=lambda o: (not o.has("science_camera"), o.name),
            )
            for other in order:
                asked.append(other.name)
                answer = await self.host.ask(
                    r, other.name, "stone", {"x": tx, "y": ty, "radius": radius}
                )
                if answer is not None and answer.get("state") in ("identified", "ground"):
                    r.knowledge.stones[answer["id"]] = dict(answer)
                    info = answer
                    break
        if info is None:
            who = f" (asked {', '.join(asked)}: none knew one)" if asked else ""
            raise self.fail(
                f"{r.name} knows no identified stone within {radius:g} m of {_fmt(tx, ty)}{who}: identify one first"
            )
        stone = w.stones[info["id"]]
        if stone.state not in ("identified", "ground"):
            r.knowledge.stones[stone.id] = stone.public()
            raise self.fail(
                f"{stone.id} is no longer there ({stone.state}{' by ' + stone.holder if stone.holder else ''})"
            )
        d = self.dist(stone.x, stone.y)
        if d > APPROACH:
            raise self.fail(
                f"{stone.id} lies {d:.0f} m away at {_fmt(stone.x, stone.y)}: drive there first (within {APPROACH:g} m)"
            )
        self.rest_eta = 90.0
        try:
            await self.move(
                ctx,
                (stone.x, stone.y),
                min(0.3, r.model.max_speed),
                tolerance=1.2,
                what=f"approaching {stone.id}",
                frac1=0.1,
            )
        finally:
            self.rest_eta = 0.0
        await self.work(ctx, 90.0, f"picking {stone.id}", load=2.0, frac0=0.1)
        if stone.state not in ("identified", "ground"):
            raise self.fail(f"{stone.id} was taken meanwhile by {stone.holder}")
        stone.state, stone.holder = "carried", r.name
        r.stones.append(stone.id)
        self._learn_stone(stone.public())
        w.log(f"{r.name} picked {stone.id} (score {stone.score:g})")
        for other in stone.identified_by:
            if other != r.name:
                await self.host.tell(r, other, "stone", stone.public())
        msg = f"picked {stone.id} (score {stone.score:g}); carrying {len(r.stones)}/{cap}"
        self.host.note(r, msg)
        ctx.progress(1.0, msg, eta_s=0.0)

    async def drop_stone(
        self, ctx: SkillContext, into: str = "lander_sample_box", **_: Any
    ) -> None:
        r, w = self.robot, self.world
        if not r.has("manipulator"):
            raise self.fail(f"{r.name} has no arm")
        if not r.stones:
            raise self.fail(f"{r.name} carries no stone")
        if into == "lander_sample_box":
            if not w.at_lander(r, 3.0):
                d = w.dist_to_lander(r.x, r.y)
                raise self.fail(
                    f"{r.name} is {d:.0f} m from the lander: drive there first (within {w.spec.lander.pad_radius + 3:g} m)"
                )
            await self.work(ctx, 60.0, "dropping into the lander's sample box", load=1.5)
            gained = 0.0
            for sid in list(r.stones):
                stone = w.stones[sid]
                stone.state, stone.holder = "delivered", None
                w.score = round(w.score + (stone.score or 0.0), 6)
                gained += stone.score or 0.0
                w.delivered.append(
                    {
                        "stone": sid,
                        "rss": stone.rss,
                        "score": stone.score or 0.0,
                        "by": r.name,
                        "sim_time": round(w.clock, 1),
                    }
                )
                self._learn_stone(stone.public())
                w.log(f"{r.name} delivered {sid}: +{stone.score:g}, score {w.score:g}")
            n = len(r.stones)
            r.stones.clear()
            msg = f"delivered {n} stone(s): +{gained:g}; score {w.score:g}"
        else:
            await self.work(ctx, 60.0, "putting the stone down", load=1.5)
            sid = r.stones.pop()
            stone = w.stones[sid]
            stone.state, stone.holder, stone.x, stone.y = (
                "ground",
                None,
                round(r.x, 2),
                round(r.y, 2),
            )
            self._learn_stone(stone.public())
            for other in stone.identified_by:
                if other != r.name:
                    await self.host.tell(r, other, "stone", stone.public())
            msg = f"put {sid} down at {_fmt(stone.x, stone.y)}"
            w.log(f"{r.name} {msg}")
        self.host.note(r, msg)
        ctx.progress(1.0, msg, eta_s=0.0)

    # ------------------------------------------------------------ payload boxes

    async def _box_moved(self, name: str) -> None:
        """LRU2 tells the others where a box is now (their world models)."""
        r, w = self.robot, self.world
        info = w.boxes[name].public()
        r.knowledge.boxes[name] = dict(info)
        w.tell_ground(r, "box", name, info)
        for other in sorted(w.robots):
            if other != r.name:
                await self.host.tell(r, other, "box", info)

    async def _take_box(
        self, ctx: SkillContext, box: str, seconds: float, frac0: float = 0.0, frac1: float = 1.0
    ) -> None:
        r, w = self.robot, self.world
        if box not in w.boxes:
            raise self.fail(
                f"there is no payload box '{box}' on this site (boxes: {', '.join(sorted(w.boxes))})"
            )
        if r.box is not None:
            raise self.fail(f"{r.name} already carries {r.box}: place it first")
        b = w.boxes[box]
        landers = [o for o in w.robots.values() if o.type == "lander" or o.kind == "static"]
        if b.where in ("shelf", "storage") or (
            r.knowledge.boxes.get(box, {}).get("where") == "shelf"
        ):
            if not w.at_lander(r, 3.0):
                d = w.dist_to_lander(r.x, r.y)
                raise self.fail(
                    f"the shelf is on the lander, {d:.0f} m away: drive there first (within {w.spec.lander.pad_radius + 3:g} m)"
                )
            shelf = None
            for lander in landers:
                shelf = await self.host.ask(r, lander.name, "shelf", {})
                if shelf is not None:
                    break
            slots = (shelf or {}).get("slots")
            if slots is not None:
                for n, info in list(r.knowledge.boxes.items()):
                    if info.get("where") == "shelf" and n not in slots.values():
                        r.knowledge.boxes.pop(n)
                for slot, n in slots.items():
                    r.knowledge.boxes[n] = {
                        **w.boxes[n].public(),
                        "where": "shelf",
                        "slot": int(slot),
                    }
                if box not in slots.values():
                    listing = ", ".join(f"{s}: {n}" for s, n in sorted(slots.items())) or "empty"
                    hint = (
                        " (it is inside the lander: shelve it with the lander's load_box)"
                        if b.where == "storage"
                        else ""
                    )
                    raise self.fail(
                        f"the lander says {box} is not on its shelf (shelf: {listing}){hint}"
                    )
            elif b.where != "shelf":
                raise self.fail(f"{box} is not on the lander's shelf")
        elif b.where == "carried":
            raise self.fail(f"{box} is carried by {b.holder}")
        else:  # on the ground
            info = r.knowledge.boxes.get(box)
            if info is None or info.get("where") != "ground":
                for other in sorted(w.robots):
                    if other == r.name:
                        continue
                    answer = await self.host.ask(r, other, "box", {"box": box})
                    if answer is not None:
                        r.knowledge.boxes[box] = dict(answer)
                        info = answer
                        break
            if info is None or info.get("where") != "ground":
                raise self.fail(
                    f"{r.name} does not know where {box} is (nobody it can reach told it)"
                )
            if math.hypot(b.x - info["x"], b.y - info["y"]) > 1.0:
                raise self.fail(
                    f"{box} is not where {r.name} believed ({_fmt(info['x'], info['y'])})"
                )
            if self.dist(b.x, b.y) > APPROACH:
                raise self.fail(
                    f"{box} lies {self.dist(b.x, b.y):.0f} m away at {_fmt(b.x, b.y)}: drive there first"
                )
            self.rest_eta = seconds
            try:
                await self.move(
                    ctx,
                    (b.x, b.y),
                    0.3,
                    tolerance=1.2,
                    what=f"approaching {box}",
                    frac0=frac0,
                    frac1=frac0,
                )
            finally:
                self.rest_eta = 0.0
        await self.work(ctx, seconds, f"picking {box}", load=2.0, frac0=frac0, frac1=frac1)
        if b.where == "carried":
            raise self.fail(f"{box} was taken meanwhile by {b.holder}")
        if b.where == "shelf":
            for lander in landers:
                lander.knowledge.boxes.pop(box, None)
        b.where, b.holder, b.slot, b.on = "carried", r.name, None, False
        r.box = box
        w.recompute_coverage()
        w.log(f"{r.name} picked {box}")
        await self._box_moved(box)

    async def pick_payload_box(self, ctx: SkillContext, box: str = "", **_: Any) -> None:
        if not self.robot.has("manipulator"):
            raise self.fail(f"{self.robot.name} has no arm to carry payload boxes")
        await self._take_box(ctx, box, 120.0)
        msg = f"carrying {box}"
        self.host.note(self.robot, f"picked {box}")
        ctx.progress(1.0, msg, eta_s=0.0)

    def _put_box(self, box: str, gx: float, gy: float) -> str:
        r, w = self.robot, self.world
        b = w.boxes[box]
        r.box = None
        b.holder = None
        used = {o.slot for o in w.boxes.values() if o.where == "shelf"}
        free = [s for s in range(1, w.spec.lander.shelf_slots + 1) if s not in used]
        if w.dist_to_lander(gx, gy) <= w.spec.lander.pad_radius and free:
            b.where, b.slot, b.x, b.y = "shelf", free[0], w.spec.lander.x, w.spec.lander.y
            for lander in w.robots.values():
                if lander.kind == "static":
                    lander.knowledge.boxes[box] = b.public()
            return f"put {box} back on the lander's shelf (slot {free[0]})"
        b.where, b.slot, b.x, b.y = "ground", None, round(r.x, 2), round(r.y, 2)
        return f"placed {box} at {_fmt(b.x, b.y)}"

    async def place_payload_box(
        self, ctx: SkillContext, box: str = "", goal: Any = None, **_: Any
    ) -> None:
        r = self.robot
        if r.box != box:
            raise self.fail(
                f"{r.name} does not carry {box}" + (f" (it carries {r.box})" if r.box else "")
            )
        gx, gy = _xy(goal)
        self.rest_eta = 60.0
        try:
            await self.move(
                ctx, (gx, gy), r.model.speed, tolerance=1.0, what=f"carrying {box}", frac1=0.7
            )
        finally:
            self.rest_eta = 0.0
        await self.work(ctx, 60.0, f"placing {box}", load=2.0, frac0=0.7)
        msg = self._put_box(box, gx, gy)
        self.world.log(f"{r.name} {msg}")
        await self._box_moved(box)
        self.host.note(r, msg)
        ctx.progress(1.0, msg, eta_s=0.0)

    async def deploy_wifi_box(
        self, ctx: SkillContext, box: str = "wifi_box_1", goal: Any = None, **_: Any
    ) -> None:
        r, w = self.robot, self.world
        if not r.has("manipulator"):
            raise self.fail(f"{r.name} has no arm to carry payload boxes")
        if box not in w.boxes or w.boxes[box].kind != "wifi":
            raise self.fail(f"{box} is not a Wi-Fi box")
        gx, gy = _xy(goal)
        if r.box != box:
            await self._take_box(ctx, box, 60.0, frac1=0.2)
        self.rest_eta = 90.0
        try:
            await self.move(
                ctx,
                (gx, gy),
                r.model.speed,
                tolerance=1.0,
                what=f"carrying {box}",
                frac0=0.2,
                frac1=0.7,
            )
        finally:
            self.rest_eta = 0.0
        await self.work(ctx, 60.0, f"placing {box}", load=2.0, frac0=0.7, frac1=0.9)
        self._put_box(box, gx, gy)
        b = w.boxes[box]
        before = float((w.coverage > 0).mean())
        await self.work(ctx, 30.0, f"switching {box} on", frac0=0.9)
        b.on = b.where == "ground"
        w.recompute_coverage()
        after = float((w.coverage > 0).mean())
        if after > before + 1e-9:
            msg = f"{box} on at {_fmt(b.x, b.y)}: coverage {_pct(before)} -> {_pct(after)} of the site"
        else:
            msg = f"{box} on at {_fmt(b.x, b.y)}, but no covered spot reaches it: coverage unchanged (place it inside coverage)"
        w.log(f"{r.name}: {msg}")
        await self._box_moved(box)
        self.host.note(r, msg)
        ctx.progress(1.0, msg, eta_s=0.0)

    # ------------------------------------------------------------ energy

    async def recharge(self, ctx: SkillContext, target_level: float = 0.95, **_: Any) -> None:
        r, w = self.robot, self.world
        self.need_kind("rover", "drone", skill="recharge")
        target_level = min(1.0, max(0.0, float(target_level)))
        if r.kind == "drone":
            if not w.docked(r):
                if not r.airborne:
                    raise self.fail(
                        f"{r.name} is on the ground {w.dist_to_lander(r.x, r.y):.0f} m from the lander pad: take off first"
                    )
                await self._fly_home(ctx, frac1=0.3)
                await self._descend(ctx, frac0=0.3, frac1=0.35)
        elif not w.at_lander(r):
            d = w.dist_to_lander(r.x, r.y)
            lx, ly = w.spec.lander.x, w.spec.lander.y
            k = max(0.0, (w.spec.lander.pad_radius - 1.5) / d)
            goal = (lx + (r.x - lx) * k, ly + (r.y - ly) * k)
            free = w.nearest_free(*goal, max_r=w.spec.lander.pad_radius) or goal

            def empty(done: float, total: float) -> str:
                left = w.dist_to_lander(r.x, r.y)
                return (
                    f"battery empty {left:.0f} m from the lander (drove {done:.0f} of {total:.0f} m): "
                    f"{r.name} is stranded"
                )

            await self.move(
                ctx,
                free,
                r.model.speed,
                tolerance=0.5,
                allow_reserve=True,
                what="returning to the lander",
                frac1=0.3,
                empty=empty,
            )
        start = r.battery
        while r.battery < target_level - 1e-9:
            dt = await self.tick(ctx)
            w.charge(r, dt, up_to=target_level)
            span = max(target_level - start, 1e-9)
            rate = r.model.charge_per_minute / 60.0
            ctx.progress(
                0.35 + 0.65 * (r.battery - start) / span,
                f"charging: {_pct(r.battery)}",
                eta_s=(target_level - r.battery) / rate,
            )
        msg = f"battery {_pct(r.battery)}"
        self.host.note(r, f"recharged: {msg}")
        ctx.progress(1.0, msg, eta_s=0.0)

    # ------------------------------------------------------------ drone

    def _need_drone(self, skill: str) -> None:
        if self.robot.kind != "drone":
            raise self.fail(f"{self.robot.name} cannot {skill}: it is not a drone")

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

    async def takeoff(self, ctx: SkillContext, altitude: float = 5.0, **_: Any) -> None:
        self._need_drone("take off")
        r = self.robot
        if not r.airborne and r.usable < 0.05:
            raise self.fail(
                f"battery {_pct(r.battery)} is too low to take off (reserve {_pct(r.model.reserve)}); recharge first"
            )
        r.airborne = True
        await self._climb(ctx, float(altitude))
        ctx.progress(1.0, f"hovering at {r.z:.0f} m", eta_s=0.0)

    async def fly_to(
        self,
        ctx: SkillContext,
        goal: Any = None,
        altitude: float = 5.0,
        speed: float = 2.0,
        **_: Any,
    ) -> None:
        self._need_drone("fly")
        r, w = self.robot, self.world
        if not r.airborne:
            raise self.fail(f"{r.name} is on the ground: take off first")
        gx, gy = _xy(goal)
        speed = self.check_speed(speed)
        d = self.dist(gx, gy)
        back = w.dist_to_lander(gx, gy)
        need_s = d / speed + abs(altitude - r.z) / CLIMB_RATE + back / r.model.speed + 40.0
        need = need_s / r.model.flight_s_per_battery
        if need > r.usable:
            reach = r.usable * r.model.flight_s_per_battery * speed
            raise self.fail(
                f"{r.name} cannot fly {d:.0f} m to {_fmt(gx, gy)} and back to the lander ({back:.0f} m): "
                f"needs {_pct(need)} of a battery, has {_pct(r.usable)} above the {_pct(r.model.reserve)} reserve "
                f"(about {reach:.0f} m); refused before the flight: land on the lander pad to recharge"
            )
        if abs(altitude - r.z) > 0.1:
            await self._climb(ctx, float(altitude), frac1=0.05)

        def empty(done: float, total: float) -> str:
            return (
                f"battery at the reserve after {done:.0f} m of {total:.0f} m: "
                f"{r.name} made an emergency landing at {_fmt(r.x, r.y)}"
            )

        await self.move(
            ctx,
            (gx, gy),
            speed,
            tolerance=0.3,
            what=f"flying to {_fmt(gx, gy)}",
            frac0=0.05,
            sense=max(r.model.nav_range, self.sensor_range() * 0.5),
            empty=empty,
        )
        yaw = _yaw(goal)
        if yaw is not None:
            r.yaw = yaw
        ctx.progress(1.0, f"hovering at {_fmt(r.x, r.y)}", eta_s=0.0)

    async def land(self, ctx: SkillContext, where: str = "lander_pad", **_: Any) -> None:
        self._need_drone("land")
        r, w = self.robot, self.world
        if not r.airborne:
            if where == "here" or w.at_lander(r):
                ctx.progress(1.0, "already on the ground", eta_s=0.0)
                return
            raise self.fail(
                f"{r.name} is on the ground {w.dist_to_lander(r.x, r.y):.0f} m from the lander pad: take off first"
            )
        if where == "lander_pad":
            await self._fly_home(ctx, frac1=0.7)
            await self._descend(ctx, frac0=0.7)
            msg = f"landed on the lander pad: charging from {_pct(r.battery)}"
        else:
            await self._descend(ctx)
            msg = f"landed at {_fmt(r.x, r.y)}"
        self.host.note(r, msg)
        ctx.progress(1.0, msg, eta_s=0.0)

    # ------------------------------------------------------------ lander

    async def load_box(self, ctx: SkillContext, box: str = "", slot: int = 1, **_: Any) -> None:
        r, w = self.robot, self.world
        if r.kind != "static":
            raise self.fail(f"{r.name} has no shelf")
        if box not in w.boxes:
            raise self.fail(
                f"there is no payload box '{box}' (boxes: {', '.join(sorted(w.boxes))})"
            )
        b = w.boxes[box]
        slot = int(slot)
        if not 1 <= slot <= w.spec.lander.shelf_slots:
            raise self.fail(f"the shelf has slots 1..{w.spec.lander.shelf_slots}")
        holder = next((o for o in w.boxes.values() if o.where == "shelf" and o.slot == slot), None)
        if holder is not None and holder.name != box:
            raise self.fail(f"slot {slot} holds {holder.name}: choose another slot")
        if b.where not in ("storage", "shelf"):
            where = (
                f"carried by {b.holder}"
                if b.where == "carried"
                else f"on the ground at {_fmt(b.x, b.y)}"
            )
            raise self.fail(f"{box} is not in the lander ({where})")
        if b.where == "shelf" and b.slot == slot:
            ctx.progress(1.0, f"{box} is on slot {slot} already", eta_s=0.0)
            return
        await self.work(ctx, 60.0, f"loading {box} onto slot {slot}")
        if b.where not in ("storage", "shelf") or any(
            o.where == "shelf" and o.slot == slot and o.name != box for o in w.boxes.values()
        ):
            raise self.fail(f"the shelf changed meanwhile: {box} not loaded")
        b.where, b.slot = "shelf", slot
        r.knowledge.boxes[box] = b.public()
        w.tell_ground(r, "box", box, b.public())
        w.log(f"{r.name} shelved {box} on slot {slot}")
        for other in sorted(w.robots.values(), key=lambda o: o.name):
            if other.has("manipulator"):
                await self.host.tell(r, other.name, "box", b.public())
        msg = f"{box} on slot {slot}"
        self.host.note(r, msg)
        ctx.progress(1.0, msg, eta_s=0.0)
