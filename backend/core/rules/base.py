"""What every family of rules shares: the refusal, what a rule decides
(`Change`), what an applied operation yields (`Applied`), and the state the
rules read (`Rules`) with the lookups that refuse when something is missing.

The families (edit, barriers, markers, execution) are functions of a `Rules`
and an operation; `backend.core.rules.engine.Engine` is the `Rules` that
dispatches operations to them and applies what they decide.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any, NamedTuple, Protocol

from backend.core import events as ev
from backend.core.alerts import RaisedAlert
from backend.core.library import Library, ParamProblem, check_params
from backend.core.limits import show_path
from backend.core.model import ACTIVE, Mission, SkillInstance, Status, how_to_change
from backend.core.ops import Operation

MAX_PROBLEMS = 5  # parameter problems named in one refusal


class Refusal(Exception):
    """An operation that would break a rule. `code` is stable; `message` is a
    sentence for a person."""

    def __init__(
        self,
        code: str,
        message: str,
        *,
        robot: str | None = None,
        skill: str | None = None,
        param: str | None = None,
    ):
        super().__init__(message)
        self.code = code
        self.message = message
        self.robot = robot
        self.skill = skill
        self.param = param

    def to_dict(self) -> dict[str, Any]:
        d = {"code": self.code, "message": self.message}
        for k in ("robot", "skill", "param"):
            if getattr(self, k) is not None:
                d[k] = getattr(self, k)
        return d


@dataclass
class Applied:
    revision: int
    events: list[ev.Event] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)  # e.g. skills still using an old marker value
    value: dict[str, Any] = field(default_factory=dict)  # e.g. {"id": "lru1-7"}
    duplicate: bool = False  # a retried request, applied before
    alerts: list[RaisedAlert] = field(default_factory=list)  # for the server to raise

    def batch(self, actor: str = "", op: str = "") -> ev.EventBatch:
        return ev.EventBatch(revision=self.revision, events=self.events, actor=actor, op=op)


class Change(NamedTuple):
    """What a rule decided, not applied yet: the events, notes for the
    operator, the value for the client, and the operation that reverts it
    (None: it cannot be undone)."""

    events: list[ev.Event]
    notes: list[str]
    value: dict[str, Any]
    undo: Operation | None
    duplicate: bool = False  # a robot's report applied before: nothing to do
    alerts: tuple[RaisedAlert, ...] = ()  # what a person must see (the server raises them)


def unchanged() -> Change:
    """A rule's answer when the operation changes nothing (no new revision)."""
    return Change([], [], {}, None)


# one rule: the state it reads and an operation of the type it is registered for
Rule = Callable[["Rules", Any], Change]


class Offers(Protocol):
    """What the robots say they can run (the server's robot link, from their
    registrations)."""

    def offered(self, robot: str) -> Mapping[str, str] | None:
        """Skill name -> the version `robot`'s manifest lists; None: it never
        registered (it refuses what it cannot run itself)."""
        ...


class Rules:
    """The mission, its library and the bookkeeping of commands in flight to
    robots; the lookups every family of rules uses. `offers` says what each
    robot can run (syncs and retries are checked against it);
    `default_expiry_s` is the expiry of a robot command that gives none."""

    def __init__(
        self,
        mission: Mission,
        library: Library,
        *,
        offers: Offers | None = None,
        default_expiry_s: float | None = None,
    ):
        self.mission = mission
        self.library = library
        self.offers = offers
        self.default_expiry_s = default_expiry_s
        # The direct path (plan_* ... release, for tools and tests; the
        # server uses the uplink): skill id -> why it cannot be edited now,
        # robot -> the command in flight to it, skill id -> values it sent
        self.held: dict[str, str] = {}
        self.pending: dict[str, str] = {}
        self.sent: dict[str, dict[str, Any]] = {}
        # ids of commands being transmitted right now (the server's): they
        # may reach the robot, so a cancel cannot be final yet
        self.transmitting: set[int] = set()
        self.clock: Callable[[], datetime] = lambda: datetime.now(UTC)
        # who submitted the operation being applied ('user@client', a robot): the
        # engine sets it; rules that record who did something read it
        self.actor = ""

    @property
    def locked(self) -> dict[str, str]:
        """Skill id -> why it cannot change now: a pending command concerns
        it (the uplink), or a direct-path command is in flight."""
        out = uplink_locks(self.mission)
        out.update(self.held)
        return out

    def robot_type(self, robot: str) -> str:
        return robot_type(self.mission, robot)

    def skill(self, skill_id: str) -> tuple[str, int, SkillInstance]:
        return find_skill(self.mission, skill_id)

    def task(self, robot: str) -> list[SkillInstance]:
        self.robot_type(robot)
        return self.mission.tasks.setdefault(robot, [])

    @staticmethod
    def first_idle(task: list[SkillInstance]) -> int:
        for i, s in enumerate(task):
            if s.status == Status.IDLE:
                return i
        return len(task)

    @staticmethod
    def first_queued(task: list[SkillInstance]) -> int | None:
        for i, s in enumerate(task):
            if s.status == Status.IDLE_SYNCHRONIZED:
                return i
        return None

    @staticmethod
    def active(task: list[SkillInstance]) -> SkillInstance | None:
        for s in task:
            if s.status in ACTIVE:
                return s
        return None

    def outside_locked(self, robot: str, task: list[SkillInstance], index: int) -> None:
        """Skills being synchronized stay at the head of the unsynchronized
        section until the robot answers: nothing may be put before them."""
        locked = self.locked
        locked_after = [s.id for s in task[index:] if s.id in locked]
        if locked_after:
            raise Refusal(
                "locked",
                f"cannot place a skill before {', '.join(locked_after)}: "
                f"being synchronized to {robot}",
                robot=robot,
            )

    def editable(self, robot: str, s: SkillInstance, doing: str) -> None:
        if s.status != Status.IDLE:
            raise Refusal(
                "not_idle",
                f"cannot {doing} {s.display()} on {robot}: it is {s.status.value}; only idle "
                f"(unsynchronized) skills can change — {how_to_change(s.status)}",
                robot=robot,
                skill=s.id,
            )
        why = self.locked.get(s.id)
        if why is not None:
            raise Refusal(
                "locked",
                f"cannot {doing} {s.display()} on {robot}: {why}",
                robot=robot,
                skill=s.id,
            )

    def check_params(
        self,
        robot: str,
        skill: str,
        params: dict[str, Any],
        bindings: dict[str, str],
        skill_id: str | None = None,
    ) -> dict[str, Any]:
        """The skill's parameters checked against the library and with bound
        values taken from their markers; refused with every problem."""
        rtype = self.robot_type(robot)
        if self.library.skill_for(rtype, skill) is None:
            offered = ", ".join(self.library.skills_of(rtype)) or "none"
            raise Refusal(
                "unknown_skill_type",
                f"robot {robot} ({rtype}) has no skill '{skill}' (it offers: {offered})",
                robot=robot,
            )
        out, problems = check_params(
            self.library,
            rtype,
            skill,
            params,
            bindings,
            markers=self.mission.markers,
            robots=set(self.mission.robots),
        )
        if problems:
            who = f"{skill_id} ({skill})" if skill_id else skill
            raise _bad_params(robot, who, skill_id, problems)
        return out


def robot_type(m: Mission, robot: str) -> str:
    """The type of `robot`, refused unless the mission has it."""
    spec = m.robots.get(robot)
    if spec is None:
        known = ", ".join(m.robots) or "none"
        raise Refusal(
            "unknown_robot", f"no robot '{robot}' in this mission (robots: {known})", robot=robot
        )
    return spec.type


def check_in_service(rules: Rules, robot: str) -> None:
    """Refused for a retired robot (no new syncs)."""
    spec = rules.mission.robots.get(robot)
    if spec is not None and spec.retired:
        raise Refusal(
            "retired",
            f"robot {robot} is retired ({spec.retired}): it gets no new syncs; give its plan "
            f"to another robot ('Give to…' in a console, or missionctl ctl reassign --from {robot} "
            "--to ROBOT)",
            robot=robot,
        )


def find_skill(m: Mission, skill_id: str) -> tuple[str, int, SkillInstance]:
    """(robot, index, skill) of `skill_id`, refused unless the mission has it."""
    found = m.find(skill_id)
    if found is None:
        raise Refusal(
            "unknown_skill", f"no skill with id '{skill_id}' in this mission", skill=skill_id
        )
    return found


def skill_of(m: Mission, robot: str, skill_id: str) -> tuple[int, SkillInstance]:
    """Index and skill `skill_id`, refused unless it is in `robot`'s list."""
    owner, i, s = find_skill(m, skill_id)
    if owner != robot:
        raise Refusal(
            "wrong_robot",
            f"skill {s.display()} belongs to {owner}, not {robot}",
            robot=robot,
            skill=s.id,
        )
    return i, s


def uplink_locks(m: Mission) -> dict[str, str]:
    """Skill id -> why it is locked, for the skills of pending commands."""
    doing = {
        "sync": "being synchronized to",
        "retry": "being retried on",
        "unsync": "being unsynchronized from",
    }
    return {
        sid: f"it is {doing[c.op]} {c.robot} (command {c.id}, {c.state.value})"
        for sid, c in m.command_locks().items()
    }


def _bad_params(
    robot: str, who: str, skill_id: str | None, problems: list[ParamProblem]
) -> Refusal:
    # every problem: a missing parameter listed first must not hide a bad value
    said = "; ".join(f"parameter {show_path(q.path)}: {q.message}" for q in problems[:MAX_PROBLEMS])
    more = f" (and {len(problems) - MAX_PROBLEMS} more)" if len(problems) > MAX_PROBLEMS else ""
    p = problems[0]
    return Refusal(
        "bad_param",
        f"{robot}, skill {who}, {said}{more}",
        robot=robot,
        skill=skill_id,
        param=str(p.path[0]) if p.path else None,
    )
