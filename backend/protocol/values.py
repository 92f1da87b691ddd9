"""What `OpReply.value` holds for each operation (documented in
docs/protocol.md; a test checks real replies against these models)."""

from __future__ import annotations

from datetime import datetime
from typing import Any, Literal

from pydantic import ConfigDict, Field

from backend.core.model import CheckId, Name, SkillId, Strict


class Empty(Strict):
    """No value: delete, move, edit, unbarrier, marker add/rename/delete."""


class Loaded(Strict):
    """load, new: what loading it as a plan changed (empty with `keep_state`)."""

    reset: list[SkillId] = Field(
        description="skills the file had synchronized (queued, active): idle again"
    )
    dissolved: list[Name] = Field(
        description="barriers left with a finished skill and an idle one: removed"
    )


class Added(Strict):
    """add, retry_edit: the new skill's id."""

    id: SkillId


class BarrierMade(Strict):
    """barrier: the new barrier's id."""

    barrier: Name


class Checked(Strict):
    """waive, unwaive: the plan check finding concerned."""

    check: CheckId


class MarkerMoved(Strict):
    """marker_move: skills bound to the marker that keep the old value
    (synchronized already: the robot has them as they were)."""

    stale: list[SkillId]


class Queued(Strict):
    """sync, unsync: the command queued in the robot's uplink. The operation
    returns here; the robot's answer comes later as events (`command_changed`)."""

    command: int = Field(description="its number, mission-wide")
    robot: Name
    seq: int = Field(description="its place in the robot's uplink")
    state: Literal["queued"]
    skills: list[SkillId] = Field(description="sync: the skills sent; unsync: those asked back")
    expires: datetime | None = Field(description="the robot never applies it later")


class RetryQueued(Queued):
    """retry: the command (skills: the failed one and the new attempt) and the
    new attempt's id; it joins the mission when the robot has it."""

    id: SkillId


class AnswerQueued(Queued):
    """answer_question: the command carrying the answer (expiring when the
    question's default applies on board) and the question's number."""

    question: int


class ControlQueued(Strict):
    """run, pause, stop, reset: per robot "queued" or why it does not apply
    (for one robot, a refusal instead), and the commands queued."""

    robots: dict[Name, str]
    commands: dict[Name, int]


class Cancelled(Strict):
    """cancel: `cancelled` at once when the command had certainly not left;
    else `queued`/`sent` with `cancel_requested` (the robot's answer decides)."""

    command: int
    robot: Name
    state: Literal["queued", "sent", "cancelled"]
    cancel_requested: bool = False


class Reverted(Strict):
    """undo / redo: what was undone or redone, plus the value of the operation
    that reverted it (an undone sync is a cancel: see cancel)."""

    model_config = ConfigDict(extra="allow")
    undone: str | None = None
    redone: str | None = None


# the operation (`op`) -> the model of its reply's value
class Joined(Strict):
    """robot_add: the robot added and its type."""

    robot: Name
    type: Name


class Retired(Strict):
    """robot_retire: its unsynchronized plan, which awaits reassignment (with
    the queued skills taken back)."""

    robot: Name
    to_reassign: list[SkillId]


class Reassigned(Strict):
    """reassign: the skills given to `to` (in their new order), why each other
    one stays, the barriers dissolved (they would tie a robot to itself), the
    `after` links dissolved for the same reason (skill -> what it awaited) and
    the barrier partners that work with `to` now (skill -> the robot its
    partner parameter named before)."""

    to: Name
    moved: list[SkillId]
    refused: dict[SkillId, str]
    dissolved: list[Name]
    afters_dissolved: dict[SkillId, SkillId] = Field(default_factory=dict)
    partners_renamed: dict[SkillId, Name] = Field(default_factory=dict)


VALUES: dict[str, type[Strict]] = {
    "add": Added,
    "retry_edit": Added,
    "delete": Empty,
    "move": Empty,
    "edit": Empty,
    "sync": Queued,
    "unsync": Queued,
    "run": ControlQueued,
    "pause": ControlQueued,
    "stop": ControlQueued,
    "reset": ControlQueued,
    "retry": RetryQueued,
    "answer_question": AnswerQueued,
    "cancel": Cancelled,
    "barrier": BarrierMade,
    "unbarrier": Empty,
    "barrier_edit": BarrierMade,
    "marker_add": Empty,
    "marker_move": MarkerMoved,
    "marker_rename": Empty,
    "marker_delete": Empty,
    "waive": Checked,
    "unwaive": Checked,
    "robot_add": Joined,
    "robot_retire": Retired,
    "reassign": Reassigned,
    "load": Loaded,
    "new": Loaded,
    "undo": Reverted,
    "redo": Reverted,
}


def check_value(op: str, value: dict[str, Any]) -> Strict:
    """The value of an `op` reply, validated (ValidationError if it does not fit)."""
    return VALUES[op].model_validate(value)
