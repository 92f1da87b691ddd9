"""The team as the console shows it (issue 30) — no Textual here: robots
that ask to join, retired robots, what "give to…" gives and the ranked list
of robots that could take it (the forecast's end, time out of comms coverage
and battery left)."""

from __future__ import annotations

from dataclasses import dataclass

from backend.core.model import Status
from backend.core.ops import Reassign
from backend.core.plan.suggest import Manifests, Suggestion, suggest, taken_words
from backend.core.rules.base import Refusal
from console.state.clock import MissionClock
from console.state.model import ConsoleModel


def joining(model: ConsoleModel) -> list[str]:
    """Robots that registered under a name the mission lacks (a known type)."""
    return [r for r, info in model.robots.items() if info.joining and not _in_mission(model, r)]


def _in_mission(model: ConsoleModel, robot: str) -> bool:
    return model.mission is not None and robot in model.mission.robots


def retired(model: ConsoleModel, robot: str | None) -> str:
    """Why `robot` was retired ('' : in service)."""
    spec = model.mission.robots.get(robot) if model.mission and robot else None
    return spec.retired if spec is not None else ""


def joining_words(model: ConsoleModel, robot: str) -> str:
    """The fleet's presence cell of a robot that asks to join."""
    info = model.robots.get(robot)
    rtype = info.manifest.type if info and info.manifest else "?"
    return f"✚ asks to join ({rtype})"


@dataclass(frozen=True)
class Gift:
    """What "give to…" gives: skill ids, or a robot's whole plan, in words."""

    ids: tuple[str, ...]
    from_robot: str | None
    words: str

    def op(self, to: str) -> Reassign:
        return Reassign(ids=list(self.ids), from_robot=self.from_robot, to=to)


def gift(model: ConsoleModel, robot: str | None, cursor: str | None, marks: list[str]) -> Gift:
    """The marked skills; else, on a retired robot, its whole plan; else the
    skill under the cursor. Raises ValueError saying why there is nothing."""
    if marks:
        return Gift(tuple(marks), None, f"{len(marks)} marked skill(s) ({', '.join(marks)})")
    if robot is not None and retired(model, robot):
        return _plan_gift(model, robot)
    found = model.find(cursor)
    if found is None:
        raise ValueError("select a skill (or mark several) to give it to another robot")
    return Gift((found[2].id,), None, found[2].display())


def _plan_gift(model: ConsoleModel, robot: str) -> Gift:
    """A retired robot's whole unsynchronized plan."""
    plan = [s.id for s in model.task(robot) if s.status == Status.IDLE]
    if not plan:
        raise ValueError(f"{robot} is retired and has no unsynchronized skill left to give")
    many = f"{len(plan)} skill" + ("s" if len(plan) != 1 else "")
    return Gift((), robot, f"{robot}'s plan ({many}: {', '.join(plan)})")


def ranked(model: ConsoleModel, g: Gift) -> list[Suggestion]:
    """The robots in service ranked for the gift (see backend/core/plan/suggest.py)."""
    return _suggest(model, _ids(model, g))


def _suggest(model: ConsoleModel, what: list[str]) -> list[Suggestion]:
    """The robots ranked for skill ids or one skill name ([]: nothing to rank)."""
    if model.mission is None or model.library is None:
        return []
    inputs = model.plan.inputs(model.telemetry, model.clock().timestamp())
    try:
        return suggest(model.mission, model.library, inputs, what, Manifests.of(model.robots))
    except Refusal:
        return []


def nobody_takes(g: Gift, hints: list[Suggestion], clock: MissionClock) -> str | None:
    """Why no robot can take the gift (None: one can)."""
    if any(h.moved for h in hints):
        return None
    why = "; ".join(f"{h.robot}: {hint_words(h, 0, clock)}" for h in hints)
    return f"no robot can take {g.words}: {why or 'no other robot in service'}"


def _ids(model: ConsoleModel, g: Gift) -> list[str]:
    """The gift's skill ids (a robot's plan: its idle skills now)."""
    return list(g.ids) or [s.id for s in model.task(g.from_robot or "") if s.status == Status.IDLE]


def hint_words(h: Suggestion, now: float, clock: MissionClock) -> str:
    """'ends 14:32 (in 12m30s), 62% battery left' / 'cannot: lru1-2: ...'."""
    if not h.moved:
        return "cannot: " + "; ".join(f"{k}: {v}" for k, v in h.refused.items())
    stays = "".join(f"; {k} stays: {v}" for k, v in h.refused.items())
    part = taken_words(len(h.moved), len(h.refused))
    return part + _end_words(h, now, clock) + battery_words(h) + coverage_words(h, clock) + stays


def _end_words(h: Suggestion, now: float, clock: MissionClock) -> str:
    if h.end is None:
        return "never ends (a barrier is never passed)"
    return f"ends {clock.ts_text(h.end)} (in {clock.duration_text(h.end - now)})"


def battery_words(h: Suggestion) -> str:
    """', 62% battery left' (and whether it was assumed full at the start)."""
    if h.battery_end is None:
        return ""
    assumed = " (no telemetry: full at start)" if h.battery_assumed else ""
    return f", {h.battery_end:.0%} battery left{assumed}"


def coverage_words(h: Suggestion, clock: MissionClock) -> str:
    """', 3m10s out of coverage' (nothing without a site map: unknown)."""
    out = h.out_of_coverage_s
    if out is None:
        return ""
    if out < 0.5:
        return ", in coverage throughout"
    return f", {clock.duration_text(out)} out of coverage"


def picker_hint(model: ConsoleModel, skill: str, robot: str) -> str:
    """For the add-skill picker: who can do `skill`, ranked as `ctl suggest`
    ranks them (a new one at the end of each plan): 'explore: ★ lru3 ends sim
    32:10, 71% left · lru1 (here) ends sim 35:00, 40% left · cannot: lru2'
    ('': nothing to rank)."""
    hints = _suggest(model, [skill])
    able = sum(h.capable for h in hints)  # ranked first
    words = [
        f"{_who(model, h, n == 0, robot)} {_bid(model, h)}" for n, h in enumerate(hints[:able])
    ]
    if able < len(hints):
        words.append(f"cannot: {', '.join(h.robot for h in hints[able:])}")
    return f"{skill}: {' · '.join(words)}" if words else ""


def _who(model: ConsoleModel, h: Suggestion, best: bool, robot: str) -> str:
    """'★ lru3', 'lru1 (here)', 'lru1 (offline)'."""
    info = model.robots.get(h.robot)
    words = [("★ " if best else "") + h.robot]
    if h.robot == robot:
        words.append("(here)")
    if info is not None and not info.online:
        words.append("(offline)")
    return " ".join(words)


def _bid(model: ConsoleModel, h: Suggestion) -> str:
    """'ends sim 32:10, 71% left, 2m out of coverage'."""
    if h.end is None:
        return "never ends"
    # an idle robot's end is about now: never before it (the two clocks differ a little)
    end = f"ends {model.clock.ts_text(max(h.end, model.clock().timestamp()))}"
    left = f", {h.battery_end:.0%} left" if h.battery_end is not None else ""
    out = h.out_of_coverage_s or 0.0
    reach = f", {model.clock.duration_text(out)} out of coverage" if out >= 0.5 else ""
    return f"{end}{left}{reach}"
