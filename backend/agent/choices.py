"""Places chosen on board: a skill's parameter bound to a marker whose place
the robot chooses (`Enqueue.choose`), before its handler runs.

The robot keeps each marker's place once it has one: its own choice or a
partner's. Before choosing it asks the marker's team (the other robots bound
to it, sent with the skill) on `missionctl.choice`; if none has a place, it
calls the integrator's hook (`RobotAgent.on_choose`), again every
`POLL_S` mission seconds while the hook does not know enough (None), up to
the rule's `wait_s`; then it tells the team. The handler gets the place
typed by the parameter's kind, and the skill's report says it
(`Report.chosen`). docs/robots.md "Places chosen on board".
"""

from __future__ import annotations

import asyncio
import inspect
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass
from typing import Any

from pydantic import ValidationError

from backend.agent.context import Execution
from backend.agent.outcomes import SkillFailed
from backend.agent.runtime import Runtime, log
from backend.agent.world import Peers
from backend.core.model import ChooseOnBoard, ChooseRule, Pose, Position

CHOICE_TOPIC = "missionctl.choice"  # ask: where is marker M? tell: M is there
POLL_S = 10.0  # mission seconds between tries while the hook does not know enough


@dataclass(frozen=True)
class Choice:
    """What a robot's choice hook is asked: the place of `marker` by `rule`,
    for parameter `param` of skill `skill_id` (`skill`); `estimate` is the
    ground's guess (what the plan was checked with)."""

    marker: str
    rule: ChooseRule
    skill_id: str
    skill: str
    param: str
    estimate: Pose | None


# the hook: a place, or None while it does not know enough yet (it is asked
# again); raising SkillFailed fails the skill with its reason
ChooseHook = Callable[[Choice], Pose | None | Awaitable[Pose | None]]


class Choices:
    """This robot's places chosen on board: see the module docstring."""

    def __init__(self, rt: Runtime, peers: Peers, scale: Callable[[], float]):
        self.rt = rt
        self.peers = peers
        self.scale = scale  # mission seconds per robot second
        self.hook: ChooseHook | None = None
        self.places: dict[str, Pose] = {}  # marker -> its place (ours or a partner's)
        self._told = asyncio.Event()  # a partner's choice arrived
        peers.add_handler("ask", CHOICE_TOPIC, self.answer)
        peers.add_handler("tell", CHOICE_TOPIC, self.on_told)

    # ------------------------------------------------------------ partners

    def answer(self, data: dict[str, Any], sender: str) -> dict[str, Any] | None:
        place = self.places.get(str(data.get("marker", "")))
        return None if place is None else {"pose": place.model_dump()}

    def on_told(self, data: dict[str, Any], sender: str) -> None:
        name = str(data.get("marker", ""))
        place = _pose(data.get("pose"))
        if name and place is not None and name not in self.places:  # the first one stays
            self.places[name] = place
            self._told.set()

    async def _from_team(self, c: ChooseOnBoard) -> Pose | None:
        for robot in c.team:
            answer = await self.peers.ask(robot, CHOICE_TOPIC, {"marker": c.marker})
            place = _pose((answer or {}).get("pose"))
            if place is not None:
                self.places.setdefault(c.marker, place)
                return self.places[c.marker]
        return None

    async def _tell_team(self, c: ChooseOnBoard, place: Pose) -> None:
        for robot in c.team:
            data = {"marker": c.marker, "pose": place.model_dump()}
            if not await self.peers.tell(robot, CHOICE_TOPIC, data):
                log.info("%s: could not tell %s its choice of %s", self.rt.name, robot, c.marker)

    # ------------------------------------------------------------ choosing

    async def resolve(
        self, act: Execution, report: Callable[[str, Mapping[str, Pose]], object]
    ) -> str | None:
        """Give each chosen parameter of the skill its place (the entry's
        params); None, else why the skill fails. `report(text, chosen)`."""
        entry = act.entry
        if not entry.choose:
            return None
        params = dict(entry.skill.params)
        chosen: dict[str, Pose] = {}
        said: list[str] = []
        for pname, c in entry.choose.items():
            place, how = await self._place(act, pname, c, report)
            if isinstance(place, str):
                return place
            params[pname] = _value(place, entry.kinds.get(pname, "pose"))
            chosen[c.marker] = place
            said.append(f"{c.marker} at ({place.x:.1f}, {place.y:.1f}) {how}")
        entry.skill = entry.skill.model_copy(update={"params": params})
        report("chose on board: " + "; ".join(said), chosen)
        return None

    async def _place(
        self,
        act: Execution,
        pname: str,
        c: ChooseOnBoard,
        report: Callable[[str, Mapping[str, Pose]], object],
    ) -> tuple[Pose | str, str]:
        """The marker's place and how it came (or why there is none)."""
        if c.marker in self.places:
            return self.places[c.marker], "(known)"
        if self.hook is None:
            return (
                f"{self.rt.name} cannot choose marker {c.marker} on board: its agent has no "
                "choice hook (register one with agent.on_choose)"
            ), ""
        report(f"choosing {c.marker} on board ({c.rule.describe()})", {})
        return await self._until_chosen(act, pname, c)

    async def _until_chosen(
        self, act: Execution, pname: str, c: ChooseOnBoard
    ) -> tuple[Pose | str, str]:
        """A partner's choice or the hook's, asked again until the rule's wait is over."""
        loop = asyncio.get_running_loop()
        end = loop.time() + c.rule.wait_s / self.scale()
        while True:
            told = await self._from_team(c)
            if told is not None:
                return told, "(a partner's choice)"
            place = await self._ask_hook(act, pname, c)
            if isinstance(place, str):
                return place, ""
            if place is not None:
                place = self.places.setdefault(c.marker, place)  # unless told meanwhile
                await self._tell_team(c, place)
                return place, "(chosen here)"
            left = end - loop.time()
            if left <= 0:
                return (
                    f"could not choose {c.marker} on board within {c.rule.wait_s:g} s "
                    f"({c.rule.describe()}): not enough known"
                ), ""
            self._told.clear()
            try:  # a partner's tell wakes it early
                await asyncio.wait_for(self._told.wait(), min(left, POLL_S / self.scale()))
            except TimeoutError:
                pass

    async def _ask_hook(self, act: Execution, pname: str, c: ChooseOnBoard) -> Pose | None | str:
        """The hook's place, None (not yet), or why it failed."""
        entry = act.entry
        choice = Choice(
            marker=c.marker,
            rule=c.rule,
            skill_id=entry.id,
            skill=entry.skill.skill,
            param=pname,
            estimate=_pose(entry.skill.params.get(pname)),
        )
        assert self.hook is not None
        try:
            value = self.hook(choice)
            if inspect.isawaitable(value):
                value = await value
        except SkillFailed as exc:
            return str(exc.reason) or f"could not choose {c.marker}"
        except Exception as exc:
            log.error("%s: the choice hook raised for %s", self.rt.name, c.marker, exc_info=True)
            return f"the choice hook raised for {c.marker}: {type(exc).__name__}: {exc}"
        return _as_place(value, c.marker)


def _as_place(value: Any, marker: str) -> Pose | None | str:
    """A hook's return value as a place, None, or what is wrong with it."""
    if value is None or isinstance(value, Pose):
        return value
    if isinstance(value, Position):
        return Pose(x=value.x, y=value.y, z=value.z)
    return f"the choice hook returned a {type(value).__name__} for {marker}: return a Pose"


def _pose(value: Any) -> Pose | None:
    """A place from a raw value (a partner's message, a parameter), or None."""
    if isinstance(value, Pose) or not isinstance(value, dict):
        return value if isinstance(value, Pose) else None
    try:
        return Pose.model_validate({k: value[k] for k in Pose.model_fields if k in value})
    except ValidationError:
        return None


def _value(place: Pose, kind: str) -> dict[str, float]:
    """The raw parameter value of a place, by the parameter's kind."""
    if kind == "position":
        return {"x": place.x, "y": place.y, "z": place.z}
    return place.model_dump()
