"""The mission model: the single source of truth for files, protocol and state.

A mission has robots, one task (ordered skill instances) per robot, barriers
tying skills of different robots together, markers (poses, positions, areas)
that parameters can be bound to, and a revision that grows with every applied
operation.
"""

from __future__ import annotations

import re
from datetime import datetime
from enum import StrEnum
from typing import Annotated, Any, Final, Literal, TypeVar

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, PrivateAttr

from backend.core.bulk import gc_paused
from backend.core.durations import duration_s, instant_s

MISSION_FORMAT: Final = "missionctl/mission@1"

# Names of robots, markers, skills and ids appear in keys (Zenoh, YAML, CLI):
# keep them to a portable character set.
NAME_PATTERN = r"^[A-Za-z][A-Za-z0-9_\-]*$"
ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_\-.]*$"
NAME_RE = re.compile(NAME_PATTERN)

Name = Annotated[str, Field(pattern=NAME_PATTERN, max_length=64)]
SkillId = Annotated[str, Field(pattern=ID_PATTERN, max_length=64)]
# a plan check's finding: "rule:subject", e.g. "barrier.deadlock:b1+b2" (backend.core.plan.checks)
CHECK_ID_PATTERN = r"^[a-z][a-z_]*\.[a-z][a-z_]*:[A-Za-z0-9][A-Za-z0-9_\-.+/]*$"
CheckId = Annotated[str, Field(pattern=CHECK_ID_PATTERN, max_length=300)]


_M = TypeVar("_M", bound=BaseModel)


def json_copy(model: _M) -> _M:
    """A copy sharing nothing with `model`, through JSON in pydantic's Rust
    code: about twice as fast as `model_copy(deep=True)`, which walks it in
    Python (a skill 39 -> 18 us, a sync's command 115 -> 60 us); JSON keeps
    every value of the mission's models (the journal relies on it)."""
    return type(model).model_validate_json(model.model_dump_json())


class Strict(BaseModel):
    """Base for every file and protocol model: unknown fields are errors."""

    # NaN/inf are no coordinates, and JSON cannot carry them
    model_config = ConfigDict(extra="forbid", validate_assignment=False, allow_inf_nan=False)


class Status(StrEnum):
    IDLE = "idle"
    IDLE_SYNCHRONIZED = "idle_synchronized"
    SYNCHWAITING = "synchwaiting"
    RUNNING = "running"
    PAUSED = "paused"
    SUCCESS = "success"
    FAILURE = "failure"


FINISHED = frozenset({Status.SUCCESS, Status.FAILURE})
ACTIVE = frozenset({Status.RUNNING, Status.PAUSED, Status.SYNCHWAITING})


def how_to_change(status: Status) -> str:
    """What an operator does to change a skill that is no longer idle."""
    if status in FINISHED:
        return (
            "finished skills are the execution log and never change; "
            "add a new skill (or retry a failed one)"
        )
    if status in ACTIVE:
        return "stop the robot (the skill goes back to its queue), then unsynchronize it"
    return "unsynchronize it first"


# Section rank: a robot's list must be sorted by it (finished log, at most one
# active, queued, unsynchronized).
SECTION_RANK: dict[Status, int] = {
    Status.SUCCESS: 0,
    Status.FAILURE: 0,
    Status.RUNNING: 1,
    Status.PAUSED: 1,
    Status.SYNCHWAITING: 1,
    Status.IDLE_SYNCHRONIZED: 2,
    Status.IDLE: 3,
}

# Status changes a robot may report (the server enforces this table).
TRANSITIONS: dict[Status, frozenset[Status]] = {
    Status.IDLE: frozenset(),  # leaves idle only through a sync acknowledgement
    Status.IDLE_SYNCHRONIZED: frozenset({Status.SYNCHWAITING, Status.RUNNING, Status.FAILURE}),
    Status.SYNCHWAITING: frozenset({Status.RUNNING, Status.IDLE_SYNCHRONIZED, Status.FAILURE}),
    Status.RUNNING: frozenset(
        {Status.PAUSED, Status.SUCCESS, Status.FAILURE, Status.IDLE_SYNCHRONIZED}
    ),
    Status.PAUSED: frozenset({Status.RUNNING, Status.IDLE_SYNCHRONIZED, Status.FAILURE}),
    Status.SUCCESS: frozenset(),
    Status.FAILURE: frozenset(),
}


# the kinds of skill parameter (what each accepts and does: backend.core.params.KINDS)
ParamType = Literal[
    "bool",
    "int",
    "float",
    "str",
    "list",
    "dict",
    "pose",
    "position",
    "area",
    "enum",
    "marker",
    "robot",
]


class Pose(Strict):
    """Euler 6D pose in the site frame (metres, radians)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0


class Position(Strict):
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


def _mission_seconds(value: Any) -> Any:
    """'10m', '1.5h', 90 -> seconds (backend.core.durations); other values as given."""
    if isinstance(value, str):
        seconds = duration_s(value)
        return value if seconds is None else seconds
    return value


# a span or an instant of mission time, in seconds; typed like any duration ("10m")
MissionSeconds = Annotated[
    float,
    Field(ge=0, le=1e10),
    BeforeValidator(_mission_seconds, json_schema_input_type=float | str),
]


def _mission_instant(value: Any) -> Any:
    """'sim 2:00:00', '2h', '2030-07-01 14:32' -> mission-clock seconds
    (backend.core.durations.instant_s); other values as given."""
    if isinstance(value, str):
        at = instant_s(value)
        return value if at is None else at
    return value


# an instant of the mission clock, in seconds (sim seconds with a simulator,
# POSIX seconds otherwise); typed like a sim clock ("sim 2:00:00") or a date
MissionInstant = Annotated[
    float,
    Field(ge=0, le=1e10),
    BeforeValidator(_mission_instant, json_schema_input_type=float | str),
]


def _unset(value: object) -> bool:
    return value is None


def _halt(value: object) -> bool:
    return value == "halt"


def _empty(value: object) -> bool:
    return not value


class ChooseRule(Strict):
    """How a robot chooses a marker's place on board, from what it knows
    (docs/robots.md "Places chosen on board"): among the regions it knows,
    pick a pair or the best, take the `rank`-th, and go to its `place`."""

    among: Literal["regions_beyond_coverage", "regions"] = Field(
        "regions_beyond_coverage",
        description="the regions to choose from: those beyond the lander's coverage, or all",
    )
    pick: Literal["closest_pair", "best_score"] = Field(
        "closest_pair",
        description="closest_pair: the two regions nearest each other (one short trip); "
        "best_score: the best revealed top scores",
    )
    rank: int = Field(1, ge=1, le=10, description="which of those picked (1: nearest the lander)")
    place: Literal["region", "approach", "relay"] = Field(
        "region",
        description="region: its centre; approach: a passable point next to it; relay: where "
        "a Wi-Fi box at the edge of coverage covers the picked regions",
    )
    ask: list[Name] = Field(
        default_factory=list,
        max_length=10,
        description="robots to ask what they know first (a survey drone)",
    )
    wait_s: MissionSeconds = Field(
        1800.0, description="mission seconds a robot may wait to know enough to choose"
    )

    def describe(self) -> str:
        """'approach to #2 of closest_pair among regions_beyond_coverage'."""
        where = "relay for" if self.place == "relay" else f"{self.place} of #{self.rank} of"
        return f"{where} {self.pick} among {self.among}"


class Chosen(Strict):
    """Who chose a marker's place on board, and when (its report's)."""

    robot: Name
    skill: SkillId
    at: datetime | None = None


def _choose_field() -> Any:
    # chosen on board: its place is the ground's estimate until a robot reports
    # its choice (`chosen`); left out of dumps while unset (files keep their form)
    return Field(
        None,
        exclude_if=_unset,
        description="chosen on board by the robot whose skill is bound to it (the value here "
        "is the ground's estimate until then)",
    )


def _chosen_field() -> Any:
    return Field(None, exclude_if=_unset, description="set when a robot reported its choice")


class _Choosable:
    """A marker a robot may choose the place of (its fields: each class's own,
    so that files keep `kind` first)."""

    @property
    def to_choose(self) -> bool:
        """Its place is still to be chosen by a robot."""
        return getattr(self, "choose", None) is not None and getattr(self, "chosen", None) is None


def on_board_text(mk: object, before: str = "", after: str = "") -> str:
    """How views say a marker chosen on board came where it is, between
    `before` and `after` ('' for any other marker): 'to be chosen on board
    (...): the place shown is an estimate' or 'chosen on board by lru1 (lru1-5)'."""
    rule: ChooseRule | None = getattr(mk, "choose", None)
    chosen: Chosen | None = getattr(mk, "chosen", None)
    if rule is None:
        return ""
    if chosen is None:
        text = f"to be chosen on board ({rule.describe()}): the place shown is an estimate"
    else:
        text = f"chosen on board by {chosen.robot} ({chosen.skill})"
    return before + text + after


class PoseMarker(Strict, _Choosable):
    kind: Literal["pose"] = "pose"
    pose: Pose
    description: str = ""
    choose: ChooseRule | None = _choose_field()
    chosen: Chosen | None = _chosen_field()


class PositionMarker(Strict, _Choosable):
    kind: Literal["position"] = "position"
    position: Position
    description: str = ""
    choose: ChooseRule | None = _choose_field()
    chosen: Chosen | None = _chosen_field()


class AreaMarker(Strict):
    kind: Literal["area"] = "area"
    area: list[Position] = Field(min_length=3)
    description: str = ""


Marker = Annotated[PoseMarker | PositionMarker | AreaMarker, Field(discriminator="kind")]


class FallbackSkill(Strict):
    """A skill the robot runs in place of a failed one (sent with the sync)."""

    skill: Name
    params: dict[str, Any] = Field(default_factory=dict)
    bindings: dict[str, Name] = Field(default_factory=dict)


class Fallback(Strict):
    """Run these skills in place of the failed one, then go on with the queue."""

    fallback: list[FallbackSkill] = Field(min_length=1, max_length=10)


class Goto(Strict):
    """Drive to this marker (a rally point) with the robot's own drive skill, then halt."""

    goto: Name


# what the robot does, on board, when a skill fails or runs out of time
# (backend.agent.contingency; docs/robots.md "Contingencies")
Branch = Literal["halt", "skip", "continue"] | Fallback | Goto


class Policies(Strict):
    """Optional per-skill policies the robot applies without a round trip."""

    retries: int = Field(0, ge=0, le=20, description="autonomous retries after a failure")
    pause_out_of_comms: bool = Field(
        False, description="pause while the robot is out of communication range"
    )
    recharge_below: float | None = Field(
        None, ge=0.0, le=1.0, description="return to recharge below this battery level (0..1)"
    )

    # the contingencies are left out of dumps while unset: a mission without
    # them is as large as before (journal snapshots, the wire)
    timeout: MissionSeconds | None = Field(
        None,
        exclude_if=_unset,
        description="mission seconds the skill may run (retries included); then on_timeout",
    )
    not_after: MissionInstant | None = Field(
        None,
        exclude_if=_unset,
        description="mission-time deadline (the mission clock: sim seconds with a simulator, "
        "POSIX seconds otherwise): not started after it, stopped at it; then on_timeout",
    )
    on_failure: Branch = Field(
        "halt",
        exclude_if=_halt,
        description="after a failure (its retries used up): halt, skip (go on with the "
        "next skill), continue (the same), fallback skills run in its place, or goto a marker",
    )
    on_timeout: Branch = Field(
        "halt",
        exclude_if=_halt,
        description="at the timeout or deadline: halt, skip (stop it, go on), continue (let "
        "it run on), fallback skills run in its place, or goto a marker",
    )

    after: SkillId | None = Field(
        None,
        exclude_if=_unset,
        description="start only once this skill of another robot succeeded (asked robot to "
        "robot); if it failed, on_failure applies",
    )

    def is_default(self) -> bool:
        return self == Policies()


class Taken(Strict):
    """The contingency branch a robot took for a skill, and why."""

    trigger: Literal["failure", "timeout"]
    branch: Literal["halt", "skip", "continue", "fallback", "goto"]
    reason: str = Field("", max_length=2000)


class SkillInstance(Strict):
    id: SkillId
    skill: Name
    label: str = ""
    params: dict[str, Any] = Field(default_factory=dict)
    # parameter name -> marker name; the value in params is the marker's value
    # at the time it was last applied to this skill.
    bindings: dict[str, Name] = Field(default_factory=dict)
    status: Status = Status.IDLE
    status_info: str = ""
    attempt: int = Field(1, ge=1)
    started_at: datetime | None = None
    finished_at: datetime | None = None
    policies: Policies = Field(default_factory=Policies)
    branch: Taken | None = Field(
        None, exclude_if=_unset, description="the contingency its robot took, if any"
    )
    # revision of the last change to this skill (optimistic concurrency)
    rev: int = Field(0, ge=0)

    def display(self) -> str:
        """How messages name a skill: its id, with the label when it has one
        (its start: a label may be thousands of characters long)."""
        label = self.label if len(self.label) <= 60 else self.label[:60] + "…"
        return f"{self.id} ({label})" if label else f"{self.id} ({self.skill})"

    def retry_id(self) -> str:
        """The id of its next attempt: lru1-4 -> lru1-4.2, lru1-4.2 -> lru1-4.3."""
        return f"{self.id.split('.')[0]}.{self.attempt + 1}"

    def next_attempt(self, status: Status = Status.IDLE) -> SkillInstance:
        """Its next attempt: the same skill, parameters, bindings and policies."""
        return SkillInstance(
            id=self.retry_id(),
            skill=self.skill,
            label=self.label,
            params=self.params,
            bindings=self.bindings,
            status=status,
            attempt=self.attempt + 1,
            policies=self.policies,
        )


class Branches(Strict):
    """A skill's fallback or goto branches, made concrete at sync: the skills
    (parameters checked, markers resolved) the robot runs for each trigger."""

    on_failure: list[SkillInstance] = Field(default_factory=list, max_length=10)
    on_timeout: list[SkillInstance] = Field(default_factory=list, max_length=10)


class RobotSpec(Strict):
    type: Name
    description: str = ""
    retired: str = Field(
        "",
        max_length=500,
        description="why it was retired (empty: in service); a retired robot gets no new "
        "syncs, its log stays and its plan awaits reassignment",
    )


class BarrierTimeout(Strict):
    """How long a robot waits at a barrier for its partners (mission time),
    and then: start alone (`continue`) or fail its skill (`halt`), on board."""

    timeout: MissionSeconds | None = Field(None, exclude_if=_unset)
    on_timeout: Literal["continue", "halt"] = Field("halt", exclude_if=_halt)


class Barrier(BarrierTimeout):
    # distinct skills of distinct robots; checked by core.checks.check_mission (files and rules)
    skills: list[SkillId] = Field(min_length=2)


# -- the uplink: commands to robots -------------------------------------------


class CommandState(StrEnum):
    """Where a command to a robot stands. `queued`: certainly not on the robot
    (never transmitted, or every transmission was refused); `sent`: it may be
    on the robot; then the robot's answer settles it: `acked` (applied),
    `refused`; or it never applies: `expired`, `cancelled`."""

    QUEUED = "queued"
    SENT = "sent"
    ACKED = "acked"
    REFUSED = "refused"
    EXPIRED = "expired"
    CANCELLED = "cancelled"


PENDING = frozenset({CommandState.QUEUED, CommandState.SENT})


class BarrierInfo(BarrierTimeout):
    """A synchronized skill's barrier: the partners' robot -> skill id, and
    how long to wait for them."""

    barrier: Name
    partners: dict[Name, SkillId]


class ChooseOnBoard(Strict):
    """A parameter of a sent skill bound to a marker chosen on board: the robot
    chooses its value before the handler runs (`RobotAgent.on_choose`)."""

    marker: Name
    rule: ChooseRule
    team: list[Name] = Field(
        default_factory=list,
        max_length=100,
        description="the other robots with skills bound to the marker: asked first, and told "
        "the choice, so that they agree",
    )


class Enqueue(Strict):
    """Queue these skills (at the head with `front`: a retry)."""

    cmd: Literal["enqueue"] = "enqueue"
    skills: list[SkillInstance] = Field(max_length=10_000)
    barriers: dict[SkillId, BarrierInfo] = Field(
        default_factory=dict, description="skill id -> its barrier and the partners to wait for"
    )
    front: bool = Field(False, description="put before the rest of the queue (retries)")
    after: dict[SkillId, Name] = Field(
        default_factory=dict,
        exclude_if=_empty,
        description="skill id -> the robot running the skill it waits for (policies.after)",
    )
    contingencies: dict[SkillId, Branches] = Field(
        default_factory=dict,
        exclude_if=_empty,
        description="skill id -> the skills its fallback / goto branches run (policies)",
    )
    choose: dict[SkillId, dict[Name, ChooseOnBoard]] = Field(
        default_factory=dict,
        exclude_if=_empty,
        description="skill id -> its parameters whose values the robot chooses on board "
        "(markers chosen on board; the value in params is the ground's estimate)",
    )
    kinds: dict[Name, dict[Name, ParamType]] = Field(
        default_factory=dict,
        description="skill name -> the kind of each of its parameters (the library's), for "
        "every skill sent: a robot types each value by its kind (a `pose` is a Pose, an "
        "`area` a list of positions...), never by its shape, and gives a handler every "
        "parameter (one left unset has no value in `params`: null)",
    )


class Dequeue(Strict):
    """Remove these queued skills; those started meanwhile stay (`kept`)."""

    cmd: Literal["dequeue"] = "dequeue"
    ids: list[SkillId] = Field(max_length=10_000)


class Run(Strict):
    cmd: Literal["run"] = "run"


class Pause(Strict):
    cmd: Literal["pause"] = "pause"


class Stop(Strict):
    cmd: Literal["stop"] = "stop"


class Reset(Strict):
    cmd: Literal["reset"] = "reset"


# -- robots ask: a skill handler's question to the operators ----------------------

MAX_QUESTION_TEXT = 500  # characters of a question
MAX_CHOICES = 9  # choices of one question (a console gives each a key, 1..9)
MAX_CHOICE = 40  # characters of one choice
# a choice: printable, no line break, no space at either end ("wider", "give up")
Choice = Annotated[
    str,
    Field(
        min_length=1,
        max_length=MAX_CHOICE,
        pattern=r"^[^\s\x00-\x1f](?:[^\x00-\x1f]*[^\s\x00-\x1f])?$",
    ),
]
# the robot's own name for one of its questions (unique per run of its agent)
AskRef = Annotated[str, Field(pattern=ID_PATTERN, max_length=64)]


class QuestionAnswer(Strict):
    """An operator's answer to one of the robot's questions (`ref`, its own name
    for it); the robot goes on with `choice` unless its default applied first."""

    cmd: Literal["answer"] = "answer"
    question: int = Field(ge=1, description="the question's number, mission-wide")
    ref: AskRef
    choice: Choice
    by: str = Field("", max_length=200, description="who answered ('user@console')")


RobotCommand = Annotated[
    Enqueue | Dequeue | Run | Pause | Stop | Reset | QuestionAnswer, Field(discriminator="cmd")
]

# what the operator asked for (`reconcile`: the server, to drop skills a robot
# holds that the mission does not give it; `answer`: a question's answer)
CommandOp = Literal[
    "sync", "unsync", "run", "pause", "stop", "reset", "retry", "reconcile", "answer"
]


class UplinkCommand(Strict):
    """One entry of a robot's uplink: a command, its place in the robot's
    sequence and where it stands. Changed only through events."""

    id: int = Field(ge=1, description="command number, mission-wide ('command 17')")
    robot: Name
    seq: int = Field(ge=1, description="per robot; the robot applies each once, in this order")
    op: CommandOp
    command: RobotCommand
    skills: list[SkillId] = Field(
        default_factory=list,
        description="the skills it concerns: sent (sync), to remove (unsync), failed and new "
        "(retry); locked while it is pending",
    )
    state: CommandState = CommandState.QUEUED
    created: datetime
    sent: datetime | None = Field(None, description="first transmission that may have reached it")
    expires: datetime | None = Field(None, description="the robot never applies it after this")
    settled: datetime | None = Field(None, description="when it left queued/sent")
    answered: datetime | None = Field(
        None, description="when the robot processed it (its clock; else when its answer came)"
    )
    cancel_requested: bool = Field(
        False, description="withdrawn while it may be on the robot: the robot's answer decides"
    )
    reason: str = Field("", description="why it was refused, expired or cancelled; robot's note")
    done: list[SkillId] = Field(
        default_factory=list, description="what the robot did: skills it queued or removed"
    )
    kept: list[SkillId] = Field(
        default_factory=list, description="unsync/reset: skills it had started, so kept"
    )

    @property
    def pending(self) -> bool:
        return self.state in PENDING

    def title(self) -> str:
        """How messages name it: 'command 17 (sync lru1-4, lru1-5)'."""
        what = f"{self.op} {', '.join(self.skills)}" if self.skills else self.op
        return f"command {self.id} ({what})"


# settled commands kept per robot (the pending ones are always kept)
KEEP_SETTLED = 20


class QuestionState(StrEnum):
    """Where a robot's question stands. `open`: asked, the robot waits (an
    operator's answer may be on its way up: `answer`); then the robot says
    how it ended: `answered` (it took the operator's answer), `defaulted`
    (its timeout came first: it went on with the default) or `withdrawn`
    (its skill stopped or ended before either)."""

    OPEN = "open"
    ANSWERED = "answered"
    DEFAULTED = "defaulted"
    WITHDRAWN = "withdrawn"


class Question(Strict):
    """A question a robot's skill asked the operators (docs/robots.md "Asking
    the operator"). Changed only through events."""

    id: int = Field(ge=1, description="its number, mission-wide ('question 3')")
    robot: Name
    ref: AskRef = Field(description="the robot's own name for it")
    skill: SkillId = Field(description="the skill whose handler asks")
    text: str = Field(min_length=1, max_length=MAX_QUESTION_TEXT)
    choices: list[Choice] = Field(min_length=2, max_length=MAX_CHOICES)
    default: Choice = Field(description="what the robot does if no answer reaches it in time")
    timeout_s: float = Field(gt=0, le=1e7, description="mission seconds it waits for an answer")
    asked: datetime = Field(description="when it asked (the robot's clock)")
    due: datetime = Field(description="when its default applies on board (the robot's clock)")
    state: QuestionState = QuestionState.OPEN
    answer: Choice | None = Field(None, description="the operator's choice (on its way while open)")
    answered_by: str = Field("", description="who answered ('user@console')")
    answered_at: datetime | None = Field(None, description="when the operator answered")
    command: int | None = Field(None, description="the uplink command carrying the answer")
    choice: Choice | None = Field(None, description="what the robot went on with, once closed")
    closed: datetime | None = Field(None, description="when the robot said how it ended")
    reason: str = Field("", max_length=2000, description="why it was withdrawn")

    @property
    def is_open(self) -> bool:
        return self.state == QuestionState.OPEN

    def title(self) -> str:
        """How messages name it: 'question 3 (lru1, lru1-4)'."""
        return f"question {self.id} ({self.robot}, {self.skill})"


class Waiver(Strict):
    """An operator's decision to synchronize despite a plan check's finding."""

    reason: str = Field(min_length=1, max_length=500)
    revision: int = Field(0, ge=0, description="the revision it was given at")


class _Hints(dict[str, tuple[str, int]]):
    """skill id -> (robot, index) where it was last seen. Only a hint, checked
    at every use, so whatever changes a task list never makes it wrong; and
    equal to any other, so two missions are equal when their content is."""

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Hints)

    __hash__ = None


NEAR = 8  # places either side of a stale hint looked at before the whole list
_OFFSETS = (0, *(k for d in range(1, NEAR + 1) for k in (-d, d)))


def _near(task: list[SkillInstance], i: int, skill_id: str) -> int | None:
    """Where `skill_id` is within NEAR places of `i` in `task` (None: not
    there). Adding or removing a skill shifts the hints of those after it by
    one; a review applying 1,300 batches rescanned 700-skill lists 120 times."""
    n = len(task)
    for d in _OFFSETS:
        j = i + d
        if 0 <= j < n and task[j].id == skill_id:
            return j
    return None


class Mission(Strict):
    format: Literal["missionctl/mission@1"] = MISSION_FORMAT
    name: str = "mission"
    library: str = Field(
        ..., description="skill library file, relative to the mission file's folder"
    )
    revision: int = Field(0, ge=0)
    robots: dict[Name, RobotSpec] = Field(default_factory=dict)
    markers: dict[Name, Marker] = Field(default_factory=dict)
    tasks: dict[Name, list[SkillInstance]] = Field(default_factory=dict)
    barriers: dict[Name, Barrier] = Field(default_factory=dict)
    waivers: dict[CheckId, Waiver] = Field(
        default_factory=dict, description="plan check id -> the waiver that lets it be synchronized"
    )
    # per-robot revision of the list's membership and order
    task_revs: dict[Name, int] = Field(default_factory=dict)
    marker_revs: dict[Name, int] = Field(default_factory=dict)
    # highest downlink sequence number applied per robot: the robot's reports
    # and answers share one sequence, applied once each, in order
    report_seqs: dict[Name, int] = Field(default_factory=dict)
    # per robot: its pending commands and the last settled ones, by seq
    uplink: dict[Name, list[UplinkCommand]] = Field(default_factory=dict)
    # highest uplink sequence number given out per robot
    uplink_seqs: dict[Name, int] = Field(default_factory=dict)
    # per robot: its robots' questions to the operators, open ones and the last
    # closed ones (left out of dumps while there are none: files keep their form)
    questions: dict[Name, list[Question]] = Field(default_factory=dict, exclude_if=_empty)
    # counters for generated ids; persisted so ids are never reused
    next_skill: int = Field(1, ge=1)
    next_barrier: int = Field(1, ge=1)
    next_command: int = Field(1, ge=1)
    next_question: int = Field(1, ge=1, exclude_if=lambda v: v == 1)
    # a 10,000-skill mission took ~0.6 ms per scan, and every status change needs one
    _hints: _Hints = PrivateAttr(default_factory=_Hints)

    # -- lookups ---------------------------------------------------------
    def find(self, skill_id: str) -> tuple[str, int, SkillInstance] | None:
        """(robot, index, skill) of a skill id, or None. O(1) for a skill
        found before whose list has not moved it; else one robot's list;
        else (a new or unknown id) every list, noted as it goes."""
        hints = self._hint_map()
        hint = hints.get(skill_id)
        if hint is not None:
            robot, i = hint
            task = self.tasks.get(robot)
            if task is not None:
                j = _near(task, i, skill_id)
                if j is not None:  # where it was, or a few places off (a skill put or
                    hints[skill_id] = (robot, j)  # taken before it): no scan of the list
                    return robot, j, task[j]
                found = self._rehint(robot, task, skill_id)  # moved further, or gone
                if found is not None:
                    return found
            del hints[skill_id]
        # not noted (a mission fresh from a file or snapshot, or an unknown id):
        # note every list in one pass, so that no other skill needs a scan
        found = None
        for robot, task in self.tasks.items():
            found = self._rehint(robot, task, skill_id) or found
        return found

    def hint(self, robot: str, index: int, skill_id: str) -> None:
        """Where a skill was just put (an added skill is found without a scan)."""
        self._hint_map()[skill_id] = (robot, index)

    def _hint_map(self) -> _Hints:
        # `self._hints` goes through pydantic's __getattr__, which probes the
        # attribute for a descriptor by raising and catching: 2.7 us against
        # 0.4, 3 times per operation; the dict that holds private values is public API
        # (never None here: pydantic sets it for every model with private attributes)
        hints: _Hints = self.__pydantic_private__["_hints"]  # type: ignore[index]
        return hints

    def _rehint(
        self, robot: str, task: list[SkillInstance], skill_id: str
    ) -> tuple[str, int, SkillInstance] | None:
        """Note where each skill of one robot's list is; return the one asked for."""
        hints = self._hint_map()
        found = None
        for i, s in enumerate(task):
            hints[s.id] = (robot, i)
            if s.id == skill_id:
                found = (robot, i, s)
        return found

    def copy_deep(self) -> Mission:
        """A copy sharing nothing with this one, made through JSON in
        pydantic's Rust code: `model_copy(deep=True)` walked a 10,000-skill
        mission in Python for ~0.4 s (JSON keeps every value: the journal's
        snapshots rely on it too)."""
        with gc_paused():
            return json_copy(self)

    def barrier_of(self, skill_id: str) -> str | None:
        for bid, b in self.barriers.items():
            if skill_id in b.skills:
                return bid
        return None

    def command(self, command_id: int) -> UplinkCommand | None:
        for cmds in self.uplink.values():
            for c in cmds:
                if c.id == command_id:
                    return c
        return None

    def command_by_seq(self, robot: str, seq: int) -> UplinkCommand | None:
        return next((c for c in self.uplink.get(robot, []) if c.seq == seq), None)

    def pending_commands(self, robot: str | None = None) -> list[UplinkCommand]:
        """Commands not settled yet (queued or sent), per robot in seq order."""
        lists = [self.uplink.get(robot, [])] if robot is not None else self.uplink.values()
        return [c for cmds in lists for c in cmds if c.pending]

    def command_locks(self) -> dict[str, UplinkCommand]:
        """Skill id -> the pending command that concerns it (a sync, an unsync
        or a retry; the oldest): the skill is locked until it settles."""
        out: dict[str, UplinkCommand] = {}
        for c in self.pending_commands():
            if c.op in ("sync", "unsync", "retry"):
                for sid in c.skills:
                    out.setdefault(sid, c)
        return out

    def question(self, question_id: int) -> Question | None:
        for qs in self.questions.values():
            for q in qs:
                if q.id == question_id:
                    return q
        return None

    def open_questions(self, robot: str | None = None) -> list[Question]:
        """Questions the robots still wait on, per robot oldest first."""
        lists = [self.questions.get(robot, [])] if robot is not None else self.questions.values()
        return [q for qs in lists for q in qs if q.is_open]

    def all_ids(self) -> set[str]:
        return {s.id for task in self.tasks.values() for s in task}


def section_problems(task: list[SkillInstance]) -> list[tuple[int, str]]:
    """Where a robot's list breaks the section order: (index, sentence)."""
    problems: list[tuple[int, str]] = []
    if not task:
        return problems
    active: int | None = None
    prev = task[0]  # the last skill in order: the others are compared with it
    for i, s in enumerate(task):
        broken = SECTION_RANK[s.status] < SECTION_RANK[prev.status]
        if broken:
            problems.append(
                (
                    i,
                    f"'{s.status.value}' after '{prev.status.value}' breaks the section order "
                    "(success/failure, then one running/paused/synchwaiting, then "
                    "idle_synchronized, then idle)",
                )
            )
        else:
            prev = s
        if s.status not in ACTIVE:
            continue
        if active is None:
            active = i
        elif not broken:
            problems.append(
                (
                    i,
                    f"second active skill: '{task[active].id}' is already "
                    f"{task[active].status.value}",
                )
            )
    return problems


def format_path(path: tuple[str | int, ...] | list[str | int]) -> str:
    """('tasks', 'lru2', 3, 'params', 'goal') -> 'tasks.lru2[3].params.goal'."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out
