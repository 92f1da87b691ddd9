"""take_science_image and identify_stone: what the science camera and the partners find."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from backend.agent import SkillContext, Success
from backend.core.model import Pose, Position
from sim.ground import RegionSeen, rss_item
from sim.objects import RssState, Stone, _fmt, newer_stone
from sim.robot import SimRobot
from sim.skills.base import SkillBase, xy

NEAR_TARGET = 5.0  # extra metres around a search radius that count as "at the target"
CAMERA_RANGE = 15.0  # science camera
IMAGE_RSS_MARGIN = 3.0  # metres around a region that an image of it may aim at
IMAGING_S = 60.0  # sim seconds one science image takes
IDENTIFY_S = 120.0  # sim seconds identifying takes, once at the search centre
# metres from the search centre a rover identifies from (it drives there first): the
# stone it identifies, at most a region's radius from the centre, stays within reach
IDENTIFY_AT = 2.0
PARTNER_WAIT = 300.0  # sim seconds one identifier waits for the other
ASK_PERIOD = 10.0  # sim seconds between asks while waiting for the partner
CAMERA_WORK = "identifying stones (science camera)"
SEARCH_S = IDENTIFY_S * 0.3  # sim seconds searching a radius for stones
# finding nothing, identify_stone asks the operators whether to search wider: a radius
# WIDER times as large, the ring around the first search taking its share of SEARCH_S
# by area; no answer within the skill's answer_within (mission time, the library's
# default 180 s) takes the default, WIDER_CHOICE
WIDER = 2.0
WIDER_CHOICE, GIVE_UP = "wider", "give up"


def _nothing_of(rss: RssState | None) -> str:
    """What a search found nothing of: the region's stones, or a region."""
    return f"no stone of {rss.name}" if rss is not None else "no region ideal for sampling stones"


@dataclass
class Search:
    """One identify_stone: where, in which region, with whom, and its share of the progress."""

    x: float
    y: float
    radius: float
    rss: RssState
    partner: str | None
    f0: float  # the progress going to the search centre took

    def at(self, frac: float) -> float:
        """The skill's progress at `frac` of the identification itself."""
        return self.f0 + (1.0 - self.f0) * frac


class ScienceSkills(SkillBase):
    """take_science_image and identify_stone handlers."""

    # ------------------------------------------------------------ take_science_image

    async def take_science_image(
        self, ctx: SkillContext, target: Pose, filter: str, camera: dict[str, Any]
    ) -> Success:
        r, w = self.robot, self.world
        if not r.has("science_camera"):
            raise self.fail(f"{r.name} has no science camera")
        tx, ty = xy(target)
        d = self.dist(tx, ty)
        if d > CAMERA_RANGE:
            raise self.fail(
                f"the target {_fmt(tx, ty)} is {d:.0f} m away; the science camera sees "
                f"{CAMERA_RANGE:.0f} m: drive closer"
            )
        if r.kind == "rover":
            r.yaw = math.atan2(ty - r.y, tx - r.x) if d > 0.1 else r.yaw
        await self.work(ctx, IMAGING_S, f"imaging {_fmt(tx, ty)} ({filter})", load=1.5)
        rss = w.rss_near(tx, ty, IMAGE_RSS_MARGIN)
        if rss is None:
            msg = f"no region ideal for sampling stones at {_fmt(tx, ty)}"
        else:
            msg = self._imaged(rss, filter)
        return self.done(ctx, msg)

    def _imaged(self, rss: RssState, filter: str) -> str:
        """What an image of `rss` tells (the top score, unless the filter is `visible`)."""
        r, w = self.robot, self.world
        info = dict(r.knowledge.rss.get(rss.name) or rss.sighting())
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
        info = r.knowledge.learn_rss(info)
        w.tell_ground(r, RegionSeen(rss_item(info)))
        return msg

    # ------------------------------------------------------------ identify_stone

    async def identify_stone(
        self,
        ctx: SkillContext,
        target: Position,
        search_radius: float,
        partner: str | None,
        answer_within: float,
    ) -> Success:
        r, w = self.robot, self.world
        tx, ty = xy(target)
        f0 = await self._reach_search_centre(ctx, tx, ty, search_radius)
        rss = w.rss_near(tx, ty, search_radius)
        if not self._reaches_a_stone(rss, tx, ty, search_radius):
            search_radius, rss = await self._search_wider(
                ctx, (tx, ty), search_radius, rss, f0, answer_within
            )
        assert rss is not None
        self._found_region(rss)
        search = Search(tx, ty, search_radius, rss, partner, f0)
        other = w.robots.get(partner) if partner else None
        if r.has("science_camera"):
            stone, how = await self._identify_by_camera(ctx, search, other)
        elif other is not None and other.has("science_camera"):
            stone, how = await self._identify_asking(ctx, search, other)
        else:
            await self.work(
                ctx, IDENTIFY_S, "identifying stones", frac0=search.at(0), frac1=search.at(1.0)
            )
            stone = self._identify(search, w.spec.scoring.min_score, (r.name,))
            how = "alone (only a low-score stone without LRU1 and LRU2 together)"
        msg = f"identified {stone.id} at {_fmt(stone.x, stone.y)}, score {stone.score:g}, {how}"
        return self.done(ctx, msg)

    def _reaches_a_stone(self, rss: RssState | None, tx: float, ty: float, radius: float) -> bool:
        """A region within `radius` of the target, with a stone there (identified or not)."""
        stones = (self.world.stones[k] for k in rss.stones) if rss is not None else ()
        return any(math.hypot(k.x - tx, k.y - ty) <= radius for k in stones)

    async def _search_wider(
        self,
        ctx: SkillContext,
        at: tuple[float, float],
        radius: float,
        rss: RssState | None,
        f0: float,
        answer_within: float,
    ) -> tuple[float, RssState]:
        """Nothing within `radius`: the operators are asked whether to search
        wider (the default, at the timeout) or give up (a failure, for the
        skill's on_failure to act on). The wider radius and its region."""
        tx, ty = at
        nothing = f"{_nothing_of(rss)} within {radius:g} m of {_fmt(tx, ty)}"
        if rss is None:
            await self.work(ctx, SEARCH_S, "searching for stones", frac0=f0, frac1=f0)
        wider = radius * WIDER
        how = await self._ask_wider(ctx, nothing, wider, answer_within)
        ring_s = SEARCH_S * (WIDER**2 - 1)  # the ring's share of the search, by area
        await self.work(ctx, ring_s, f"searching wider ({wider:g} m, {how})", frac0=f0, frac1=f0)
        found = self.world.rss_near(tx, ty, wider)
        if found is None or not self._reaches_a_stone(found, tx, ty, wider):
            raise self.fail(f"{nothing}, nor within {wider:g} m: nothing to identify here")
        return wider, found

    async def _ask_wider(
        self, ctx: SkillContext, nothing: str, wider: float, answer_within: float
    ) -> str:
        """The operators' word (or the default): how the wider search was
        decided; a failure saying who gave up."""
        reply = await ctx.ask_operator(
            f"{self.robot.name}: {nothing}. Search wider ({wider:g} m)?",
            [WIDER_CHOICE, GIVE_UP],
            WIDER_CHOICE,
            answer_within,
        )
        if reply.choice == GIVE_UP:
            by = f" ({reply.by})" if reply.by else ""
            raise self.fail(f"{nothing}: nothing to identify here; the operator{by} gave up")
        return "answered" if reply.answered else "by default"

    async def _reach_search_centre(
        self, ctx: SkillContext, tx: float, ty: float, radius: float
    ) -> float:
        """A rover far from the search centre goes there first (part of the skill).
        Returns the share of the progress that took."""
        r = self.robot
        if r.kind != "rover":
            self._near_target(tx, ty, radius, "search centre")
            return 0.0
        if self.dist(tx, ty) <= IDENTIFY_AT:
            return 0.0
        await self.move_before(
            ctx,
            IDENTIFY_S,
            (tx, ty),
            r.model.speed,
            tolerance=IDENTIFY_AT,
            what="going to the search centre",
            frac1=0.3,
        )
        return 0.3

    def _found_region(self, rss: RssState) -> None:
        """The robot's first visit to `rss`: it learns the region and tells the ground."""
        r, w = self.robot, self.world
        if r.name in rss.found_by:
            return
        rss.found_by.add(r.name)
        info = r.knowledge.learn_rss(rss.sighting())
        w.tell_ground(r, RegionSeen(rss_item(info)))
        w.log(f"{r.name} discovered {rss.name} at {_fmt(rss.x, rss.y)}")

    async def _identify_by_camera(
        self, ctx: SkillContext, s: Search, other: SimRobot | None
    ) -> tuple[Stone, str]:
        """The science camera picks the stone; with the manipulator next to it, the best one."""
        r = self.robot
        await self.work(ctx, IDENTIFY_S * 0.8, CAMERA_WORK, frac0=s.at(0), frac1=s.at(0.8))
        waited = 0.0
        while self._manipulator_coming(s, other) and waited < PARTNER_WAIT:
            await self.work(
                ctx,
                self.dt,
                f"waiting for {s.partner} to reach the search centre",
                frac0=s.at(0.8),
                frac1=s.at(0.8),
            )
            waited += self.dt
        collab = self._collaborating(s.partner, s.x, s.y, "manipulator")
        earlier = await self._partners_stone(s)
        if earlier is not None:  # the partners name one stone: never use up two
            how = f"{s.partner} had identified it alone (only a low-score stone)"
            stone = earlier
        else:
            stone = self._identify(
                s,
                s.rss.max_score if collab else self.world.spec.scoring.min_score,
                (r.name, s.partner) if collab and s.partner else (r.name,),
            )
            how = (
                f"with {s.partner}"
                if collab
                else "alone (only a low-score stone without the manipulator)"
            )
        await self.work(ctx, IDENTIFY_S * 0.2, CAMERA_WORK, frac0=s.at(0.8), frac1=s.at(1.0))
        return stone, how

    async def _partners_stone(self, s: Search) -> Stone | None:
        """The stone the partner already identified alone in this search (it gave up
        waiting), if it tells which: the camera names that one too."""
        r, w = self.robot, self.world
        alone = {
            k.id
            for k in (w.stones[i] for i in s.rss.stones)
            if k.state == "identified"
            and k.identified_by == (s.partner,)
            and math.hypot(k.x - s.x, k.y - s.y) <= s.radius
        }
        if not alone or s.partner is None:
            return None
        where = {"x": s.x, "y": s.y, "radius": s.radius, "exclude": r.knowledge.gone_stones()}
        answer = await self.host.ask(r, s.partner, "stone", where)
        if answer is None or answer.get("id") not in alone:
            return None
        r.knowledge.learn_stone(answer)
        stone = w.stones[answer["id"]]
        stone.identified_by = (*stone.identified_by, r.name)
        return stone

    def _manipulator_coming(self, s: Search, other: SimRobot | None) -> bool:
        """The partner with the manipulator works on this skill but is not here yet."""
        return (
            other is not None
            and other.has("manipulator")
            and other.activity == "identify_stone"
            and not self._collaborating(s.partner, s.x, s.y, "manipulator")
        )

    async def _identify_asking(
        self, ctx: SkillContext, s: Search, other: SimRobot
    ) -> tuple[Stone, str]:
        """LRU2 asks LRU1 which stone it identified (polling while LRU1 works on it)."""
        r = self.robot
        await self.work(
            ctx,
            IDENTIFY_S * 0.85,
            f"identifying stones with {s.partner}",
            frac0=s.at(0),
            frac1=s.at(0.85),
        )
        answer = await self._ask_for_the_stone(ctx, s, other)
        if answer is not None:
            r.knowledge.learn_stone(answer)
            stone = self.world.stones[answer["id"]]
            together = r.name in stone.identified_by
            if not together:
                stone.identified_by = (*stone.identified_by, r.name)
            how = (
                f"with {s.partner}: it told where the stone lies"
                if together
                else f"{s.partner} had identified it alone (only a low-score stone) and told "
                "where it lies"
            )
        else:
            stone = self._identify(s, self.world.spec.scoring.min_score, (r.name,))
            how = f"alone ({s.partner} did not point out a stone)"
        await self.work(
            ctx, IDENTIFY_S * 0.15, "locating the stone", frac0=s.at(0.85), frac1=s.at(1.0)
        )
        return stone, how

    async def _ask_for_the_stone(
        self, ctx: SkillContext, s: Search, other: SimRobot
    ) -> dict[str, Any] | None:
        """Ask `other` until it names a stone it identified, while it works on the skill
        (not one this robot knows is gone: its own news of a stone beats older news)."""
        r = self.robot
        waited = 0.0
        while True:
            where = {
                "x": s.x,
                "y": s.y,
                "radius": s.radius,
                "exclude": r.knowledge.gone_stones(),
            }
            answer = await self.host.ask(r, other.name, "stone", where)
            if (
                answer is not None
                and answer.get("state") == "identified"
                and newer_stone(r.knowledge.stones.get(answer["id"]), answer)
            ):
                return answer
            busy = other.activity == "identify_stone"
            if waited >= (PARTNER_WAIT if busy else IDENTIFY_S * 0.15):
                return None
            step = min(ASK_PERIOD, PARTNER_WAIT - waited)
            await self.work(
                ctx,
                step,
                f"waiting for {s.partner} to point out the stone",
                frac0=s.at(0.85),
                frac1=s.at(0.85),
            )
            waited += step

    # ------------------------------------------------------------ shared steps

    def _near_target(self, tx: float, ty: float, radius: float, what: str) -> None:
        d = self.dist(tx, ty)
        if d > radius + NEAR_TARGET:
            raise self.fail(
                f"{self.robot.name} is {d:.0f} m from the {what} {_fmt(tx, ty)}: drive there first "
                f"(within {radius + NEAR_TARGET:.0f} m)"
            )

    def _collaborating(self, partner: str | None, tx: float, ty: float, need: str) -> bool:
        """`partner` (with `need`) identifies too, and both are near the search centre."""
        if not partner:
            return False
        other = self.world.robots.get(partner)
        if other is None or not other.has(need) or other.activity != "identify_stone":
            return False
        if not self.world.can_talk(self.robot, other):
            return False  # together means talking: through the network (or direct radio)
        rng = self.world.spec.scoring.collab_range
        return math.hypot(other.x - tx, other.y - ty) <= rng and self.dist(tx, ty) <= rng

    def _identify(self, s: Search, score: float, by: tuple[str, ...]) -> Stone:
        """The hidden stone of the region nearest the search centre, within the search
        radius: identified now."""
        w, name = self.world, s.rss.name
        hidden = [w.stones[k] for k in s.rss.stones if w.stones[k].state == "hidden"]
        if not hidden:
            raise self.fail(f"every stone of {name} is identified already: try another region")
        near = [k for k in hidden if math.hypot(k.x - s.x, k.y - s.y) <= s.radius]
        if not near:
            raise self.fail(
                f"no stone to identify within {s.radius:g} m of {_fmt(s.x, s.y)} in {name}: "
                "search wider (search_radius) or aim elsewhere in the region"
            )
        stone = min(near, key=lambda k: (math.hypot(k.x - s.x, k.y - s.y), k.id))
        stone.change(score=score, state="identified", identified_by=by)
        self.learn_stone(stone.public())
        w.log(f"{' and '.join(by)} identified {stone.id} in {name} (score {score:g})")
        return stone
