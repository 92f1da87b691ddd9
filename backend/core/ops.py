"""Operations: what operators and robots ask the mission to do.

Operator operations come from consoles and `ctl`; robot operations are the
acknowledgements and reports of robot agents, applied by the server. Both are
validated by `backend.core.rules.engine.Engine`; these models are also the protocol.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal

from pydantic import AwareDatetime, Field, model_validator

from backend.core.model import (
    MAX_CHOICES,
    MAX_QUESTION_TEXT,
    AreaMarker,
    AskRef,
    Barrier,
    BarrierTimeout,
    CheckId,
    Choice,
    CommandState,
    Marker,
    Mission,
    Name,
    Policies,
    Pose,
    PoseMarker,
    Position,
    PositionMarker,
    SkillId,
    SkillInstance,
    Status,
    Strict,
    Taken,
)

# -- operator operations -------------------------------------------------------


class AddSkill(Strict):
    op: Literal["add"] = "add"
    robot: Name
    skill: Name
    label: str = ""
    params: dict[str, Any] = Field(default_factory=dict)
    bindings: dict[str, Name] = Field(default_factory=dict)
    policies: Policies | None = None
    at: int | None = Field(
        None, description="index within the unsynchronized section; end if omitted"
    )


class DeleteSkills(Strict):
    op: Literal["delete"] = "delete"
    ids: list[SkillId] = Field(min_length=1)


class MoveSkill(Strict):
    op: Literal["move"] = "move"
    id: SkillId
    index: int = Field(ge=0, description="new index within the unsynchronized section")


class EditSkill(Strict):
    op: Literal["edit"] = "edit"
    id: SkillId
    label: str | None = None
    params: dict[str, Any] = Field(default_factory=dict, description="values to change")
    bindings: dict[str, Name | None] = Field(
        default_factory=dict, description="bind a parameter to a marker; null unbinds"
    )
    policies: Policies | None = None


# a command's expiry, on every operation that sends one to a robot
ExpireS = Annotated[
    float | None,
    Field(
        ge=0,
        le=10 * 365 * 86400,
        description="seconds until the command expires: the robot never applies it later "
        "(omitted: the server's default; 0: never)",
    ),
]


class Predicted(Strict):
    """When the plan's forecast had a skill start and end."""

    start: datetime
    end: datetime


class Sync(Strict):
    op: Literal["sync"] = "sync"
    robot: Name
    through: SkillId | None = Field(
        None, description="last skill to synchronize; all idle if omitted"
    )
    expire_s: ExpireS = None
    forecast: dict[SkillId, Predicted] = Field(
        default_factory=dict,
        max_length=10_000,
        description="the skills' predicted start and end as the synchronizing client's "
        "forecast had them: journaled with the operation, so a review draws the plan "
        "against what happened (the server does not use it)",
    )


class Unsync(Strict):
    op: Literal["unsync"] = "unsync"
    robot: Name
    from_id: SkillId | None = Field(
        None, description="first queued skill to take back; all if omitted"
    )
    expire_s: ExpireS = None


class Control(Strict):
    op: Literal["run", "pause", "stop", "reset"]
    robot: Name | None = Field(None, description="one robot, or every robot if omitted")
    expire_s: ExpireS = None


class Retry(Strict):
    op: Literal["retry"] = "retry"
    id: SkillId
    expire_s: ExpireS = None


class Cancel(Strict):
    """Withdraw a pending command: final at once while it is certainly not on
    the robot (queued); else a request the robot's answer settles."""

    op: Literal["cancel"] = "cancel"
    command: int = Field(ge=1, description="the command number")
    undo: bool = Field(False, description="an undo of a sync: refused unless still queued")


class RetryEdit(Strict):
    """A failed skill's next attempt as an idle copy (same parameters,
    bindings and policies, attempt + 1, id `ID.N`) at the head of its robot's
    unsynchronized plan, to edit before it is synchronized; `retry` instead
    queues the attempt on the robot at once."""

    op: Literal["retry_edit"] = "retry_edit"
    id: SkillId


class AddBarrier(BarrierTimeout):
    op: Literal["barrier"] = "barrier"
    ids: list[SkillId] = Field(min_length=2)


class RemoveBarrier(Strict):
    op: Literal["unbarrier"] = "unbarrier"
    barrier: Name


class EditBarrier(BarrierTimeout):
    """Set how long a barrier's robots wait for each other (mission time) and
    what follows (`continue`: start alone; `halt`: fail); every skill of the
    barrier must be idle (a synchronized one's robot holds the old ones)."""

    op: Literal["barrier_edit"] = "barrier_edit"
    barrier: Name


class MarkerAdd(Strict):
    op: Literal["marker_add"] = "marker_add"
    name: Name
    marker: Marker


class MarkerMove(Strict):
    op: Literal["marker_move"] = "marker_move"
    name: Name
    value: Pose | Position | list[Position] = Field(
        description="new pose, position or area polygon (same kind as the marker)"
    )


class MarkerRename(Strict):
    op: Literal["marker_rename"] = "marker_rename"
    name: Name
    new_name: Name


class MarkerDelete(Strict):
    op: Literal["marker_delete"] = "marker_delete"
    name: Name


class Waive(Strict):
    """Let skills with this plan check's finding be synchronized (errors
    otherwise refuse the sync); given again, the reason is replaced."""

    op: Literal["waive"] = "waive"
    check: CheckId = Field(description="the finding's id, e.g. 'barrier.deadlock:b1+b2'")
    reason: str = Field(min_length=1, max_length=500, description="why, for the log")


class Unwaive(Strict):
    op: Literal["unwaive"] = "unwaive"
    check: CheckId


class AddRobot(Strict):
    """Add a robot to the mission: one that registered under a new name with a
    type the library knows (the server announces it), or one to come."""

    op: Literal["robot_add"] = "robot_add"
    name: Name
    type: Name
    description: str = Field("", max_length=500)


class RetireRobot(Strict):
    """Retire a robot: no new syncs; its queued skills are taken back (by its
    uplink, or on the ground while it is offline) and its unsynchronized plan
    awaits reassignment; its log stays."""

    op: Literal["robot_retire"] = "robot_retire"
    name: Name
    reason: str = Field(min_length=1, max_length=500, description="why, for the log")
    expire_s: ExpireS = None


class Reassign(Strict):
    """Give idle skills (`ids`, or the whole unsynchronized plan of `from_robot`)
    to robot `to`, keeping parameters, bindings and order; each skill that
    cannot move says why (the others move)."""

    op: Literal["reassign"] = "reassign"
    ids: list[SkillId] = Field(default_factory=list, max_length=10_000)
    from_robot: Name | None = Field(None, description="its whole unsynchronized plan")
    to: Name


class AnswerQuestion(Strict):
    """Answer a robot's open question with one of its choices: the answer
    goes up the robot's uplink like any command (it expires when the
    question's default applies on board); the robot says which it took."""

    op: Literal["answer_question"] = "answer_question"
    question: int = Field(ge=1, description="the question's number")
    choice: Choice = Field(description="one of the choices it offers")


class LoadMission(Strict):
    """Replace the mission. It comes in as a plan: every skill that is not
    finished is idle (its status was the robots' once; what they hold now is
    theirs to say), finished ones stay as the log. `keep_state` keeps the
    file's statuses: refused while a robot of the mission is online."""

    op: Literal["load"] = "load"
    mission: Mission
    keep_state: bool = Field(
        False, description="keep the file's statuses (refused while a robot of it is online)"
    )


class NewMission(Strict):
    op: Literal["new"] = "new"
    name: str = "mission"


class Undo(Strict):
    op: Literal["undo"] = "undo"


class Redo(Strict):
    op: Literal["redo"] = "redo"


# -- internal operations (undo/redo), never sent by clients --------------------


class RestoreItem(Strict):
    robot: Name
    index: int
    skill: SkillInstance


class RestoreSkills(Strict):
    op: Literal["restore_skills"] = "restore_skills"
    items: list[RestoreItem]
    barriers: dict[Name, Barrier] = Field(default_factory=dict)


class SetSkill(Strict):
    op: Literal["set_skill"] = "set_skill"
    id: SkillId
    label: str
    params: dict[str, Any]
    bindings: dict[str, Name]
    policies: Policies


class ReturnSkills(Strict):
    """The undo of a reassignment: each skill back where it was, with the
    barriers it was in, its `after` links and its partners' parameters."""

    op: Literal["return_skills"] = "return_skills"
    items: list[RestoreItem]
    to: Name = Field(description="where the reassignment gave them (its redo)")
    barriers: dict[Name, Barrier] = Field(default_factory=dict)
    afters: dict[SkillId, SkillId] = Field(
        default_factory=dict,
        max_length=10_000,
        description="skill id -> the `after` it had, dissolved by the reassignment",
    )
    partners: dict[SkillId, Name] = Field(
        default_factory=dict,
        max_length=10_000,
        description="barrier partner skill id -> the robot its partner parameter (talks_to) "
        "named before the reassignment named `to` there",
    )


class RestoreMarker(Strict):
    op: Literal["restore_marker"] = "restore_marker"
    name: Name
    marker: Marker
    bindings: list[tuple[SkillId, str]] = Field(
        default_factory=list, description="(skill, parameter) to bind again"
    )


class RestoreBarrier(BarrierTimeout):
    op: Literal["restore_barrier"] = "restore_barrier"
    barrier: Name
    skills: list[SkillId]


# -- robot operations (applied by the server on behalf of a robot) -------------


class SyncAck(Strict):
    op: Literal["sync_ack"] = "sync_ack"
    robot: Name
    ids: list[SkillId]


class UnsyncDone(Strict):
    op: Literal["unsync_done"] = "unsync_done"
    robot: Name
    ids: list[SkillId] = Field(description="skills the robot removed from its queue")


class RetryAck(Strict):
    op: Literal["retry_ack"] = "retry_ack"
    robot: Name
    failed_id: SkillId
    skill: SkillInstance


class QueueEntry(Strict):
    """A skill a robot holds (its registration lists them, the active one first)."""

    id: SkillId
    status: Status
    skill: Name | None = Field(None, description="its skill name (lets the ground compare)")
    params: dict[str, Any] | None = Field(None, description="its parameters, as the robot has them")


class Reconcile(Strict):
    """A robot (re)registered holding `queue`: the mission is made to agree
    with it. Skills the mission holds as synchronized that the robot lacks
    return to the plan; skills it holds that the mission has as idle are
    adopted (synchronized again); skills the mission does not give it are
    asked back (a `reconcile` command)."""

    op: Literal["reconcile"] = "reconcile"
    robot: Name
    queue: list[QueueEntry] = Field(max_length=10_000)
    asking: list[AskRef] | None = Field(
        None,
        max_length=1000,
        exclude_if=lambda v: v is None,
        description="the questions it still asks (None: it did not say); the mission's "
        "other open questions of it are withdrawn",
    )


class UplinkSent(Strict):
    """Server: these queued commands were transmitted and may be on the robot."""

    op: Literal["uplink_sent"] = "uplink_sent"
    robot: Name
    ids: list[int]
    at: datetime


class UplinkSettle(Strict):
    """Server: these commands never reached the robot and never will:
    expired, or cancelled (their cancel was asked while they were on their way)."""

    op: Literal["uplink_settle"] = "uplink_settle"
    robot: Name
    ids: list[int]
    state: Literal[CommandState.EXPIRED, CommandState.CANCELLED]
    reason: str
    at: datetime


class DownlinkRefused(Strict):
    """Server: a robot's downlink message `seq` was refused (its reason is
    here and alerted): its number is used up, the sequence goes on."""

    op: Literal["downlink_refused"] = "downlink_refused"
    robot: Name
    seq: int = Field(ge=1)
    code: str
    message: str


class Answer(Strict):
    """A robot's answer to a command of its uplink: what it actually did.
    Numbered in the same sequence as its reports."""

    op: Literal["answer"] = "answer"
    robot: Name
    seq: int = Field(ge=1, description="downlink sequence number (shared with reports)")
    command: int = Field(ge=1, description="the command's uplink seq")
    outcome: Literal["applied", "refused", "expired", "cancelled"]
    reason: str = Field("", max_length=2000, description="why not applied, or a note")
    queued: list[SkillId] = Field(default_factory=list, description="enqueue: the ids it holds")
    removed: list[SkillId] = Field(
        default_factory=list, description="dequeue/reset: the ids it removed"
    )
    kept: list[SkillId] = Field(
        default_factory=list, description="dequeue: asked to remove, but started: kept"
    )
    at: AwareDatetime | None = Field(None, description="when it was processed (robot's clock)")


class Report(Strict):
    """A robot's status change for one skill, numbered per robot."""

    op: Literal["report"] = "report"
    robot: Name
    seq: int = Field(ge=1)
    id: SkillId
    status: Status
    info: str = ""
    attempt: int | None = Field(None, ge=1)
    at: AwareDatetime | None = Field(None, description="when it changed (robot's clock)")
    branch: Taken | None = Field(
        None,
        exclude_if=lambda v: v is None,
        description="the contingency it took (policies on_failure / on_timeout), and why",
    )
    chosen: dict[Name, Pose] = Field(
        default_factory=dict,
        max_length=100,
        exclude_if=lambda v: not v,
        description="markers chosen on board for this skill -> the place the robot chose "
        "(or took from a partner's choice)",
    )


def choices_problem(choices: list[str], default: str) -> str | None:
    """What is wrong with a question's choices and default, or None."""
    if len(set(choices)) != len(choices):
        return f"choices {choices} repeat one"
    if default not in choices:
        return f"the default {default!r} is not one of the choices {choices}"
    return None


class Ask(Strict):
    """A robot's question to the operators, asked by a skill's handler
    (`ctx.ask_operator`); numbered with its reports. It waits `timeout_s` of
    mission time, then goes on with `default` and says so (`AskEnded`)."""

    op: Literal["ask"] = "ask"
    robot: Name
    seq: int = Field(ge=1, description="downlink sequence number (shared with reports)")
    ref: AskRef = Field(description="the robot's own name for the question (unique per run)")
    skill: SkillId = Field(description="the skill whose handler asks")
    text: str = Field(min_length=1, max_length=MAX_QUESTION_TEXT)
    choices: list[Choice] = Field(min_length=2, max_length=MAX_CHOICES)
    default: Choice
    timeout_s: float = Field(gt=0, le=1e7, description="mission seconds it waits")
    at: AwareDatetime = Field(description="when it asked (robot's clock)")
    due: AwareDatetime = Field(description="when the default applies (robot's clock)")

    @model_validator(mode="after")
    def _choices(self) -> Ask:
        problem = choices_problem(self.choices, self.default)
        if problem is not None:
            raise ValueError(problem)
        return self


class AskEnded(Strict):
    """A robot's question ended without the operator's answer: its default
    applied at the timeout, or its skill stopped or ended (withdrawn)."""

    op: Literal["ask_ended"] = "ask_ended"
    robot: Name
    seq: int = Field(ge=1, description="downlink sequence number (shared with reports)")
    ref: AskRef
    outcome: Literal["default", "withdrawn"]
    choice: Choice | None = Field(None, description="default: the choice it went on with")
    reason: str = Field("", max_length=2000)
    at: AwareDatetime | None = Field(None, description="when (robot's clock)")


# what clients may send; what robots' answers become; everything the engine applies
OperatorOperation = (
    AddSkill
    | DeleteSkills
    | MoveSkill
    | EditSkill
    | Sync
    | Unsync
    | Control
    | Retry
    | Cancel
    | RetryEdit
    | AddBarrier
    | RemoveBarrier
    | EditBarrier
    | MarkerAdd
    | MarkerMove
    | MarkerRename
    | MarkerDelete
    | Waive
    | Unwaive
    | AddRobot
    | RetireRobot
    | Reassign
    | AnswerQuestion
    | LoadMission
    | NewMission
    | Undo
    | Redo
)
InternalOperation = RestoreSkills | SetSkill | RestoreBarrier | RestoreMarker | ReturnSkills
RobotOperation = SyncAck | UnsyncDone | RetryAck | Reconcile | Report | Answer | Ask | AskEnded
# what the server applies for the uplink (never sent by clients or robots)
LinkOperation = UplinkSent | UplinkSettle | DownlinkRefused
Operation = OperatorOperation | InternalOperation | RobotOperation | LinkOperation

# the same, as pydantic reads them (by their `op`)
OperatorOp = Annotated[OperatorOperation, Field(discriminator="op")]
RobotOp = Annotated[RobotOperation, Field(discriminator="op")]
AnyOp = Annotated[Operation, Field(discriminator="op")]
# what a robot sends on its downlink: its reports, its answers and its
# questions, one sequence
DownlinkMessage = Annotated[Report | Answer | Ask | AskEnded, Field(discriminator="op")]

# operations that change the unsynchronized plan and can be undone (a sync:
# while its command is still queued, its undo is a cancel)
UNDOABLE = (
    AddSkill,
    Sync,
    RetryEdit,
    DeleteSkills,
    MoveSkill,
    EditSkill,
    AddBarrier,
    RemoveBarrier,
    EditBarrier,
    MarkerAdd,
    MarkerMove,
    MarkerRename,
    MarkerDelete,
    RestoreSkills,
    SetSkill,
    RestoreBarrier,
    RestoreMarker,
    Waive,
    Unwaive,
    Reassign,
    ReturnSkills,
)

MARKER_TYPES = {"pose": PoseMarker, "position": PositionMarker, "area": AreaMarker}
