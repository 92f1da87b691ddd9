"""drive_to and explore: rovers drive, rovers and drones map an area."""

from __future__ import annotations

import math

import numpy as np

from backend.agent import SkillContext, SkillFailed, Success
from backend.core.model import Pose, Position
from sim.objects import _fmt
from sim.pathing import ROCK, lawnmower
from sim.robot import SimRobot
from sim.skills.base import DRONE_MARGIN_S, SkillBase, pct, xy
from sim.world import World

MAPPED = 0.995  # the share of the area's cells that counts as all of it
LANE_SPACING = 1.6  # explore lanes lie this many sensor ranges apart


class Survey:
    """One explore: the cells to map, its clock, and the way back it keeps time for."""

    def __init__(
        self,
        robot: SimRobot,
        world: World,
        cells: np.ndarray,
        max_duration: float,
        return_to_start: bool,
    ):
        rows_i, cols_j = np.nonzero(cells)
        # the area's bounding box on the grid: counting mapped cells looks only there
        self.window = (
            slice(int(rows_i.min()), int(rows_i.max()) + 1),
            slice(int(cols_j.min()), int(cols_j.max()) + 1),
        )
        self.mask = cells[self.window]
        self.cells = int(self.mask.sum())
        self.robot, self.world = robot, world
        self.max_duration = max_duration
        self.return_to_start = return_to_start
        self.start = (robot.x, robot.y)
        self.speed = robot.model.speed
        self.t0 = robot.sim_seconds
        self._mapped_at = -1.0  # sim seconds when `mapped` was counted: once per step
        self._mapped = 0.0

    def elapsed(self) -> float:
        return self.robot.sim_seconds - self.t0

    def mapped(self) -> float:
        """The share of the area's cells explored so far."""
        if self._mapped_at != self.robot.sim_seconds:
            self._mapped_at = self.robot.sim_seconds
            explored = self.world.explored[self.window] & self.mask
            self._mapped = float(explored.sum()) / self.cells
        return self._mapped

    def back_time(self) -> float:
        if not self.return_to_start:
            return 0.0
        r = self.robot
        return math.hypot(r.x - self.start[0], r.y - self.start[1]) / self.speed

    def out_of_time(self) -> bool:
        return self.elapsed() + self.back_time() >= self.max_duration

    def budget(self) -> float:
        """Sim seconds left for the sweep (the way back to the start kept aside)."""
        return self.max_duration - self.elapsed() - self.back_time()

    def done(self) -> bool:
        return self.mapped() >= MAPPED or self.out_of_time()

    def drone_must_return(self) -> bool:
        r = self.robot
        if r.kind != "drone":
            return False
        way_back = self.world.dist_to_lander(r.x, r.y) / r.model.speed + DRONE_MARGIN_S
        return r.usable <= way_back / r.model.flight_s_per_battery

    def should_stop(self) -> bool:
        return self.done() or self.drone_must_return()

    def report(self, ctx: SkillContext) -> None:
        f = self.mapped()
        ctx.progress(
            min(0.99, max(self.elapsed() / self.max_duration, f)),
            f"exploring: {pct(f)} mapped",
            eta_s=max(0.0, self.max_duration - self.elapsed()),
        )


class MobilitySkills(SkillBase):
    """drive_to and explore handlers."""

    async def drive_to(
        self, ctx: SkillContext, goal: Pose, speed: float, tolerance: float
    ) -> Success:
        self.need_kind("rover", skill="drive")
        r = self.robot
        gx, gy = xy(goal)
        speed = self.check_speed(speed)
        await self.move(
            ctx, (gx, gy), speed, tolerance=tolerance, what=f"driving to {_fmt(gx, gy)}"
        )
        if self.dist(gx, gy) <= max(tolerance, 1.0):
            r.yaw = goal.yaw
        return self.done(ctx, f"at {_fmt(r.x, r.y)}, battery {pct(r.battery)}")

    async def explore(
        self,
        ctx: SkillContext,
        area: list[Position],
        max_duration: float,
        return_to_start: bool,
        sensors: list[str],
    ) -> Success:
        r = self.robot
        poly = self._area_to_explore(area, sensors)
        rng = self.sensor_range()
        survey = Survey(r, self.world, self._mappable(poly), max_duration, return_to_start)
        lanes = lawnmower(poly, spacing=LANE_SPACING * rng, start=survey.start)
        found_before = len(r.knowledge.rss)
        self._look_around(rng)
        await self._sweep(ctx, survey, lanes, rng)
        low = survey.drone_must_return()
        if return_to_start and self.dist(*survey.start) > 1.0:
            await self.move(
                ctx,
                survey.start,
                survey.speed,
                tolerance=1.0,
                sense=rng,
                discover=True,
                what="returning",
            )
        summary = self._survey_summary(survey, found_before)
        if low:
            raise self.fail(
                f"stopped exploring: {summary}; {r.name} needs its remaining "
                f"{pct(r.battery)} battery to fly back to the lander"
            )
        return self.done(ctx, summary)

    def _area_to_explore(
        self, area: list[Position], sensors: list[str]
    ) -> list[tuple[float, float]]:
        """The area's corners, once the robot can explore it with these sensors."""
        r = self.robot
        self.need_kind("rover", "drone", skill="explore")
        if r.kind == "drone" and not r.airborne:
            raise self.fail(f"{r.name} is on the ground: take off first")
        if not isinstance(area, list) or len(area) < 3:
            raise self.fail("the area needs at least three corners")
        poly = [xy(p) for p in area]
        self._check_sensors(sensors)
        return poly

    def _check_sensors(self, sensors: list[str]) -> None:
        """The robot has every sensor asked for (each has the stereo camera)."""
        r = self.robot
        known = set(r.model.capabilities) | {"stereo_camera"}
        for s in sensors:
            if str(s) not in known:
                raise self.fail(
                    f"{r.name} has no sensor '{s}' (it has: {', '.join(sorted(known))})"
                )

    def _mappable(self, poly: list[tuple[float, float]]) -> np.ndarray:
        """The grid cells of the area this robot can map (a rover: not the impassable ones)."""
        w = self.world
        cells = w.geom.polygon_mask(poly)
        if self.robot.kind != "drone":
            cells &= w.terrain.grid != ROCK
        if not cells.any():
            raise self.fail(
                "the area holds no cell this robot can map (too small, or all impassable)"
            )
        return cells

    def _look_around(self, rng: float) -> None:
        r, w = self.robot, self.world
        w.reveal(r, rng)
        for name in w.discover(r, rng):
            self.host.note(r, f"found {name}")

    async def _sweep(
        self, ctx: SkillContext, survey: Survey, lanes: list[tuple[float, float]], rng: float
    ) -> None:
        """Follow the lanes until the area is mapped, the time is up or a drone must go home."""
        r, w = self.robot, self.world
        for wp in lanes:
            if survey.done() or survey.drone_must_return():
                break
            target = wp if r.kind == "drone" else w.terrain.nearest_free(*wp, max_r=rng)
            if target is not None:
                await self._sweep_to(ctx, survey, target, rng)

    async def _sweep_to(
        self, ctx: SkillContext, survey: Survey, target: tuple[float, float], rng: float
    ) -> None:
        """Map the way to a lane's end; one it cannot reach is left out (a battery
        run out is not)."""
        try:
            await self.move(
                ctx,
                target,
                survey.speed,
                tolerance=1.0,
                sense=rng,
                discover=True,
                what="exploring",
                stop_when=survey.should_stop,
                report=lambda: survey.report(ctx),
                budget=survey.budget,
            )
        except SkillFailed:
            if self.robot.usable <= 0:
                raise

    def _survey_summary(self, survey: Survey, found_before: int) -> str:
        found = list(self.robot.knowledge.rss)[found_before:]
        summary = f"explored {pct(survey.mapped())} of the area in {survey.elapsed():.0f} s"
        if found:
            return summary + f"; found {', '.join(found)}"
        return summary + "; no new region ideal for sampling stones"
