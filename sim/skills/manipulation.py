"""pick_stone, drop_stone, payload boxes, the Wi-Fi box and the lander's load_box."""

from __future__ import annotations

import math
from typing import Any

from backend.agent import SkillContext, SkillFailed, Success
from backend.core.model import Pose, Position
from backend.protocol import mapfeed as mf
from sim.exchange import best_first, pickable_near
from sim.ground import BoxSeen, Delivered, box_item
from sim.objects import BoxState, Stone, _fmt
from sim.robot import SimRobot
from sim.skills.base import SkillBase, pct, xy

APPROACH = 8.0  # a stone/box this close is approached within the skill
STONE_SEARCH = 6.0  # metres around pick_stone's target where a known stone counts ...
REGION_MARGIN = 2.0  # ... or, aimed inside a region the robot knows, the region and this
LANDER_REACH = 3.0  # metres beyond the lander pad from which the arm reaches the lander
PICKABLE = ("identified", "ground")  # states of a stone an arm can pick


class ManipulationSkills(SkillBase):
    """pick_stone, drop_stone, the payload boxes (pick, place, deploy a Wi-Fi box) and
    the lander's load_box."""

    # ------------------------------------------------------------ stones

    async def pick_stone(self, ctx: SkillContext, target: Position, region: str | None) -> Success:
        r, w = self.robot, self.world
        if not r.has("manipulator"):
            raise self.fail(f"{r.name} has no arm to pick stones")
        tx, ty = xy(target)
        cap = self._capacity()
        if len(r.stones) >= cap:
            raise self.fail(
                f"{r.name} already carries {len(r.stones)} stone(s) (capacity {cap}"
                f"{'' if r.box else '; carry a sample box for more'}): drop first"
            )
        stone = await self._stone_to_pick(tx, ty, region)
        d = self.dist(stone.x, stone.y)
        if d > APPROACH:
            raise self.fail(
                f"{stone.id} lies {d:.0f} m away at {_fmt(stone.x, stone.y)}: drive there first "
                f"(within {APPROACH:g} m)"
            )
        picking_s = 90.0
        await self.move_before(
            ctx,
            picking_s,
            (stone.x, stone.y),
            min(0.3, r.model.max_speed),
            tolerance=1.2,
            what=f"approaching {stone.id}",
            frac1=0.1,
        )
        await self.work(ctx, picking_s, f"picking {stone.id}", load=2.0, frac0=0.1)
        if stone.state not in PICKABLE:
            raise self.fail(f"{stone.id} was taken meanwhile by {stone.holder}")
        stone.change(state="carried", holder=r.name)
        r.stones.append(stone.id)
        self.learn_stone(stone.public())
        w.log(f"{r.name} picked {stone.id} (score {stone.score:g})")
        await self._tell_identifiers(stone)
        return self.done(
            ctx,
            f"picked {stone.id} of {stone.rss} (score {stone.score:g}); "
            f"carrying {len(r.stones)}/{cap}",
        )

    def _capacity(self) -> int:
        r = self.robot
        if r.box is not None and self.world.boxes[r.box].kind == "sample":
            return r.model.carry_stones_in_box
        return r.model.carry_stones

    async def _stone_to_pick(self, tx: float, ty: float, region: str | None) -> Stone:
        """The stone near the target this robot knows of, or learns of by asking."""
        r = self.robot
        radius = self._pick_radius(tx, ty)
        info = self._known_stone(tx, ty, radius, region)
        asked: list[str] = []
        if info is None:
            info, asked = await self._ask_for_a_stone(tx, ty, radius)
        if info is None:
            who = f" (asked {', '.join(asked)}: none knew one)" if asked else ""
            raise self.fail(
                f"{r.name} knows no identified stone within {radius:g} m of "
                f"{_fmt(tx, ty)}{who}: identify one first"
            )
        stone = self.world.stones[info["id"]]
        if stone.state not in PICKABLE:
            self.learn_stone(stone.public())
            by = f" by {stone.holder}" if stone.holder else ""
            raise self.fail(f"{stone.id} is no longer there ({stone.state}{by})")
        return stone

    def _pick_radius(self, tx: float, ty: float) -> float:
        """How far from the target a known stone counts: the whole region the target
        lies in (as the robot knows it), at least STONE_SEARCH."""
        radius = STONE_SEARCH
        for rss in self.robot.knowledge.rss.values():
            if math.hypot(rss["x"] - tx, rss["y"] - ty) <= rss["radius"]:
                reach = math.hypot(rss["x"] - tx, rss["y"] - ty) + rss["radius"] + REGION_MARGIN
                radius = max(radius, reach)
        return radius

    def _known_stone(
        self, tx: float, ty: float, radius: float, region: str | None
    ) -> dict[str, Any] | None:
        """The best-scored pickable stone near the target in the robot's world model
        (of `region` if it knows one there), the nearest among equals."""
        cands = [
            s for s in self.robot.knowledge.stones.values() if pickable_near(s, tx, ty, radius)
        ]
        if region:
            cands = [s for s in cands if s.get("rss") == region] or cands
        return min(cands, key=lambda s: best_first(s, tx, ty), default=None)

    async def _ask_for_a_stone(
        self, tx: float, ty: float, radius: float
    ) -> tuple[dict[str, Any] | None, list[str]]:
        """Ask the other mobile robots (science camera first) for a pickable stone near
        the target: the first answer newer than what this robot knows, and who was asked."""
        r = self.robot
        asked: list[str] = []
        for other in self._stone_askers():
            asked.append(other.name)
            where = {"x": tx, "y": ty, "radius": radius, "exclude": r.knowledge.gone_stones()}
            answer = await self.host.ask(r, other.name, "stone", where)
            if answer is not None and answer.get("state") in PICKABLE:
                if r.knowledge.learn_stone(answer):  # else its own news of the stone is newer
                    return answer, asked
        return None, asked

    def _stone_askers(self) -> list[SimRobot]:
        """The other mobile robots, those with a science camera first."""
        r = self.robot
        return sorted(
            (o for o in self.world.robots.values() if o.name != r.name and o.kind != "static"),
            key=lambda o: (not o.has("science_camera"), o.name),
        )

    async def _tell_identifiers(self, stone: Stone) -> None:
        """The robots that identified `stone` learn where it is now."""
        r = self.robot
        for other in stone.identified_by:
            if other != r.name:
                await self.host.tell(r, other, "stone", stone.public())

    async def drop_stone(self, ctx: SkillContext, into: str) -> Success:
        r = self.robot
        if not r.has("manipulator"):
            raise self.fail(f"{r.name} has no arm")
        if not r.stones:
            raise self.fail(f"{r.name} carries no stone")
        if into == "lander_sample_box":
            msg = await self._deliver(ctx)
        else:
            msg = await self._put_stone_down(ctx)
        return self.done(ctx, msg)

    async def _deliver(self, ctx: SkillContext) -> str:
        """Every carried stone into the lander's sample box: each one scores."""
        r, w = self.robot, self.world
        if not w.at_lander(r, LANDER_REACH):
            d = w.dist_to_lander(r.x, r.y)
            raise self.fail(
                f"{r.name} is {d:.0f} m from the lander: drive there first "
                f"(within {w.spec.lander.pad_radius + LANDER_REACH:g} m)"
            )
        await self.work(ctx, 60.0, "dropping into the lander's sample box", load=1.5)
        parts = []
        for sid in list(r.stones):
            stone = w.stones[sid]
            stone.change(state="delivered", holder=None)
            score = stone.score or 0.0
            w.score = round(w.score + score, 6)
            delivery = mf.Delivery(
                stone=sid, rss=stone.rss, score=score, by=r.name, sim_time=round(w.now(), 1)
            )
            w.delivered.append(delivery)
            self.learn_stone(stone.public())
            w.tell_ground(r, Delivered(delivery))
            w.log(f"{r.name} delivered {sid}: +{score:g}, score {w.score:g}")
            parts.append(f"{sid} of {stone.rss} +{score:g}")
            await self._tell_identifiers(stone)
        r.stones.clear()
        gained = round(sum(d.score for d in w.delivered[-len(parts) :]), 6)
        return f"delivered {', '.join(parts)}: +{gained:g}; score {w.score:g}"

    async def _put_stone_down(self, ctx: SkillContext) -> str:
        """The last stone picked onto the ground where the robot stands."""
        r, w = self.robot, self.world
        await self.work(ctx, 60.0, "putting the stone down", load=1.5)
        sid = r.stones.pop()
        stone = w.stones[sid]
        stone.change(state="ground", holder=None, x=round(r.x, 2), y=round(r.y, 2))
        self.learn_stone(stone.public())
        await self._tell_identifiers(stone)
        msg = f"put {sid} down at {_fmt(stone.x, stone.y)}"
        w.log(f"{r.name} {msg}")
        return msg

    # ------------------------------------------------------------ payload boxes

    async def pick_payload_box(self, ctx: SkillContext, box: str) -> Success:
        if not self.robot.has("manipulator"):
            raise self.fail(f"{self.robot.name} has no arm to carry payload boxes")
        await self._take_box(ctx, box, 120.0)
        return self.done(ctx, f"picked {box}: carrying it")

    async def place_payload_box(self, ctx: SkillContext, box: str, goal: Pose) -> Success:
        r = self.robot
        if r.box != box:
            raise self.fail(
                f"{r.name} does not carry {box}" + (f" (it carries {r.box})" if r.box else "")
            )
        gx, gy = xy(goal)
        placing_s = 60.0
        await self.move_before(
            ctx,
            placing_s,
            (gx, gy),
            r.model.speed,
            tolerance=1.0,
            what=f"carrying {box}",
            frac1=0.7,
        )
        await self.work(ctx, placing_s, f"placing {box}", load=2.0, frac0=0.7)
        msg = self._put_box(box, gx, gy)
        self.world.log(f"{r.name} {msg}")
        await self._box_moved(box)
        return self.done(ctx, msg)

    async def deploy_wifi_box(self, ctx: SkillContext, box: str, goal: Pose) -> Success:
        r, w = self.robot, self.world
        if not r.has("manipulator"):
            raise self.fail(f"{r.name} has no arm to carry payload boxes")
        if box not in w.boxes or w.boxes[box].kind != "wifi":
            raise self.fail(f"{box} is not a Wi-Fi box")
        gx, gy = xy(goal)
        if r.box != box:
            await self._take_box(ctx, box, 60.0, frac1=0.2)
        await self.move_before(
            ctx,
            90.0,  # placing, then switching on
            (gx, gy),
            r.model.speed,
            tolerance=1.0,
            what=f"carrying {box}",
            frac0=0.2,
            frac1=0.7,
        )
        await self.work(ctx, 60.0, f"placing {box}", load=2.0, frac0=0.7, frac1=0.9)
        self._put_box(box, gx, gy)
        msg = await self._switch_on(ctx, box)
        w.log(f"{r.name}: {msg}")
        await self._box_moved(box)
        return self.done(ctx, msg)

    async def _switch_on(self, ctx: SkillContext, box: str) -> str:
        """A placed Wi-Fi box on the ground covers its range, if it is itself covered."""
        w = self.world
        b = w.boxes[box]
        before = float((w.coverage > 0).mean())
        await self.work(ctx, 30.0, f"switching {box} on", frac0=0.9)
        b.on = b.where == "ground"
        w.recompute_coverage()
        after = float((w.coverage > 0).mean())
        at = f"{box} on at {_fmt(b.x, b.y)}"
        if after > before + 1e-9:
            return f"{at}: coverage {pct(before)} -> {pct(after)} of the site"
        return (
            f"{at}, but no covered spot reaches it: coverage unchanged (place it inside coverage)"
        )

    async def _take_box(
        self, ctx: SkillContext, box: str, seconds: float, frac0: float = 0.0, frac1: float = 1.0
    ) -> None:
        """Pick `box` from the lander's shelf or the ground (approached within the skill)."""
        r, w = self.robot, self.world
        b = self._box_to_take(box)
        landers = [o for o in w.robots.values() if o.type == "lander" or o.kind == "static"]
        await self._reach_box(ctx, b, landers, seconds, frac0)
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

    def _box_to_take(self, box: str) -> BoxState:
        """The box named, if there is one and the robot's arm is free."""
        r, w = self.robot, self.world
        if box not in w.boxes:
            raise self.fail(
                f"there is no payload box '{box}' on this site "
                f"(boxes: {', '.join(sorted(w.boxes))})"
            )
        if r.box is not None:
            raise self.fail(f"{r.name} already carries {r.box}: place it first")
        return w.boxes[box]

    async def _reach_box(
        self, ctx: SkillContext, b: BoxState, landers: list[SimRobot], seconds: float, frac0: float
    ) -> None:
        """Within reach of `b`: at the lander's shelf (as the robot believes), or at
        the box on the ground; carried by another robot: no."""
        believed_on_shelf = self.robot.knowledge.boxes.get(b.name, {}).get("where") == "shelf"
        if b.where in ("shelf", "storage") or believed_on_shelf:
            await self._check_shelf(b, landers)
        elif b.where == "carried":
            raise self.fail(f"{b.name} is carried by {b.holder}")
        else:  # on the ground
            await self._approach_box(ctx, b, seconds, frac0)

    async def _check_shelf(self, b: BoxState, landers: list[SimRobot]) -> None:
        """At the lander, the lander says `b` is on its shelf (the robot learns the shelf)."""
        r, w = self.robot, self.world
        if not w.at_lander(r, LANDER_REACH):
            d = w.dist_to_lander(r.x, r.y)
            raise self.fail(
                f"the shelf is on the lander, {d:.0f} m away: drive there first "
                f"(within {w.spec.lander.pad_radius + LANDER_REACH:g} m)"
            )
        slots = await self._ask_shelf(landers)
        if slots is None:
            if b.where != "shelf":
                raise self.fail(f"{b.name} is not on the lander's shelf")
            return
        self._learn_shelf(slots)
        if b.name not in slots.values():
            raise self._not_on_shelf(b, slots)

    def _not_on_shelf(self, b: BoxState, slots: dict[str, str]) -> SkillFailed:
        """The lander's shelf, as it said, does not hold `b`."""
        listing = ", ".join(f"{s}: {n}" for s, n in sorted(slots.items())) or "empty"
        hint = (
            " (it is inside the lander: shelve it with the lander's load_box)"
            if b.where == "storage"
            else ""
        )
        return self.fail(f"the lander says {b.name} is not on its shelf (shelf: {listing}){hint}")

    async def _ask_shelf(self, landers: list[SimRobot]) -> dict[str, str] | None:
        """Slot -> box on the shelf, from the first lander that answers (None: none did)."""
        shelf = None
        for lander in landers:
            shelf = await self.host.ask(self.robot, lander.name, "shelf", {})
            if shelf is not None:
                break
        return (shelf or {}).get("slots")

    def _learn_shelf(self, slots: dict[str, str]) -> None:
        """The robot's world model follows the shelf the lander described."""
        r, w = self.robot, self.world
        for n, info in list(r.knowledge.boxes.items()):
            if info.get("where") == "shelf" and n not in slots.values():
                r.knowledge.boxes.pop(n)
        for slot, n in slots.items():
            r.knowledge.boxes[n] = {**w.boxes[n].public(), "where": "shelf", "slot": int(slot)}

    async def _approach_box(
        self, ctx: SkillContext, b: BoxState, seconds: float, frac0: float
    ) -> None:
        """Go to `b` on the ground, where the robot believes it is (asking others if it
        does not know), if that is near."""
        r = self.robot
        info = await self._where_is(b.name)
        if info is None or info.get("where") != "ground":
            raise self.fail(
                f"{r.name} does not know where {b.name} is (nobody it can reach told it)"
            )
        if math.hypot(b.x - info["x"], b.y - info["y"]) > 1.0:
            raise self.fail(
                f"{b.name} is not where {r.name} believed ({_fmt(info['x'], info['y'])})"
            )
        if self.dist(b.x, b.y) > APPROACH:
            raise self.fail(
                f"{b.name} lies {self.dist(b.x, b.y):.0f} m away at {_fmt(b.x, b.y)}: "
                "drive there first"
            )
        await self.move_before(
            ctx,
            seconds,
            (b.x, b.y),
            0.3,
            tolerance=1.2,
            what=f"approaching {b.name}",
            frac0=frac0,
            frac1=frac0,
        )

    async def _where_is(self, box: str) -> dict[str, Any] | None:
        """Where the robot believes `box` lies; not on the ground: the first other robot
        that answers tells it."""
        r = self.robot
        info = r.knowledge.boxes.get(box)
        if info is not None and info.get("where") == "ground":
            return info
        for other in sorted(self.world.robots):
            if other == r.name:
                continue
            answer = await self.host.ask(r, other, "box", {"box": box})
            if answer is not None:
                r.knowledge.boxes[box] = dict(answer)
                return answer
        return info

    def _put_box(self, box: str, gx: float, gy: float) -> str:
        r, w = self.robot, self.world
        b = w.boxes[box]
        r.box = None
        b.holder = None
        slot = self._shelf_slot_at(gx, gy)
        if slot is not None:
            return self._shelve(b, slot)
        b.where, b.slot, b.x, b.y = "ground", None, round(r.x, 2), round(r.y, 2)
        return f"placed {box} at {_fmt(b.x, b.y)}"

    def _shelf_slot_at(self, gx: float, gy: float) -> int | None:
        """The first free slot of the shelf, when (gx, gy) is on the lander's pad."""
        w = self.world
        if w.dist_to_lander(gx, gy) > w.spec.lander.pad_radius:
            return None
        used = {o.slot for o in w.boxes.values() if o.where == "shelf"}
        free = [s for s in range(1, w.spec.lander.shelf_slots + 1) if s not in used]
        return free[0] if free else None

    def _shelve(self, b: BoxState, slot: int) -> str:
        """`b` back on the shelf: the landers see it there."""
        w = self.world
        b.where, b.slot, b.x, b.y = "shelf", slot, w.spec.lander.x, w.spec.lander.y
        for lander in w.robots.values():
            if lander.kind == "static":
                lander.knowledge.boxes[b.name] = b.public()
        return f"put {b.name} back on the lander's shelf (slot {slot})"

    async def _box_moved(self, name: str) -> None:
        """LRU2 tells the others where a box is now (their world models)."""
        r, w = self.robot, self.world
        info = w.boxes[name].public()
        r.knowledge.boxes[name] = dict(info)
        w.tell_ground(r, BoxSeen(box_item(info)))
        for other in sorted(w.robots):
            if other != r.name:
                await self.host.tell(r, other, "box", info)

    # ------------------------------------------------------------ the lander's shelf

    async def load_box(self, ctx: SkillContext, box: str, slot: int) -> Success:
        r, w = self.robot, self.world
        b, slot = self._loadable(box, slot)
        if b.where == "shelf" and b.slot == slot:
            return self.done(ctx, f"{box} is on slot {slot} already")
        await self.work(ctx, 60.0, f"loading {box} onto slot {slot}")
        if b.where not in ("storage", "shelf") or self._slot_holder(slot, box) is not None:
            raise self.fail(f"the shelf changed meanwhile: {box} not loaded")
        b.where, b.slot = "shelf", slot
        r.knowledge.boxes[box] = b.public()
        w.tell_ground(r, BoxSeen(box_item(b.public())))
        w.log(f"{r.name} shelved {box} on slot {slot}")
        for other in sorted(w.robots.values(), key=lambda o: o.name):
            if other.has("manipulator"):
                await self.host.tell(r, other.name, "box", b.public())
        return self.done(ctx, f"{box} on the shelf, slot {slot}")

    def _slot_holder(self, slot: int, box: str) -> BoxState | None:
        """Another box than `box` on that shelf slot (None: the slot is free for it)."""
        return next(
            (
                o
                for o in self.world.boxes.values()
                if o.where == "shelf" and o.slot == slot and o.name != box
            ),
            None,
        )

    def _loadable(self, box: str, slot: int) -> tuple[BoxState, int]:
        """The box inside the lander and the free shelf slot it goes to, or why not."""
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
        holder = self._slot_holder(slot, box)
        if holder is not None:
            raise self.fail(f"slot {slot} holds {holder.name}: choose another slot")
        if b.where not in ("storage", "shelf"):
            raise self.fail(f"{box} is not in the lander ({_outside_text(b)})")
        return b, slot


def _outside_text(b: BoxState) -> str:
    """Where a box outside the lander is: carried, or on the ground."""
    return (
        f"carried by {b.holder}" if b.where == "carried" else f"on the ground at {_fmt(b.x, b.y)}"
    )
