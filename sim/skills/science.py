"""take_science_image and identify_stone: what the science camera and the partners find."""

from __future__ import annotations

import math
from typing import Any

from backend.agent import SkillContext, Success
from sim.skills.base import SkillBase, xy
from sim.world import Stone, _fmt

NEAR_TARGET = 5.0  # extra metres around a search radius that count as "at the target"
CAMERA_RANGE = 15.0  # science camera
PARTNER_WAIT = 300.0  # sim seconds one identifier waits for the other
ASK_PERIOD = 10.0  # sim seconds between asks while waiting for the partner


class ScienceSkills(SkillBase):
    """take_science_image and identify_stone handlers."""

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
        tx, ty = xy(target)
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
        self.learn_stone(stone.public())
        w.log(f"{' and '.join(by)} identified {stone.id} in {rss_name} (score {score:g})")
        return stone

    async def identify_stone(
        self,
        ctx: SkillContext,
        target: Any = None,
        search_radius: float = 3.0,
        partner: str | None = None,
        **_: Any,
    ) -> Success:
        r, w = self.robot, self.world
        tx, ty = xy(target)
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
                self.learn_stone(answer)
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
