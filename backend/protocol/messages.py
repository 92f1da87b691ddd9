"""The wire protocol's messages (JSON from these models); the key space is in `keys`.

Documented for third parties in docs/protocol.md (generated sections come
from these models). Bump PROTOCOL_VERSION on any incompatible change.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal

from pydantic import Field, ValidationError

from backend.core.events import EventBatch
from backend.core.library import Library
from backend.core.model import Mission, Name, Pose, SkillId, SkillInstance, Status, Strict
from backend.core.ops import OperatorOp, Report
from backend.protocol.keys import PROTOCOL_VERSION

# -- consoles and ctl -> server -------------------------------------------------


class Request(Strict):
    client: str = Field(description="stable id of the client (console, ctl run)")
    request_id: str = Field(description="unique per client; a retried request is applied once")
    user: str = ""
    expected_revision: int | None = Field(
        None,
        description="revision the client saw; a change to what the op touches after it is refused",
    )
    op: OperatorOp


class OpReply(Strict):
    ok: Literal[True] = True
    revision: int
    value: dict[str, Any] = Field(default_factory=dict)
    notes: list[str] = Field(default_factory=list)
    duplicate: bool = False


class ErrorReply(Strict):
    """A refusal (reply_err payload). `code` is stable; `message` is a sentence."""

    ok: Literal[False] = False
    code: str
    message: str
    robot: str | None = None
    skill: str | None = None
    param: str | None = None


class AccountInfo(Strict):
    """What the server knows of a logged-in user (answer on `Keys.account(user)`)."""

    user: str
    role: Literal["operator", "observer", "robot"]
    robots: list[Name] = Field(
        default_factory=list, description="robot accounts: the robots they may act as"
    )
    enforced: bool = Field(
        True,
        description="false: the server runs without accounts "
        "(anyone may do anything; role is nominal)",
    )


class StateRequest(Strict):
    protocol: int = PROTOCOL_VERSION
    client: str = ""


class Module(Strict):
    name: Name
    version: str = Field(pattern=r"^\d+\.\d+\.\d+")


class Manifest(Strict):
    """What a robot says about itself when it registers."""

    name: Name
    type: Name
    protocol: int = PROTOCOL_VERSION
    modules: list[Module] = Field(default_factory=list)
    properties: dict[str, Any] = Field(default_factory=dict)
    skills: dict[Name, str] = Field(
        default_factory=dict, description="skill name -> implemented version (SemVer)"
    )


class RobotInfo(Strict):
    """The server's view of a robot: presence and manifest."""

    name: Name
    online: bool = False
    since: datetime | None = Field(None, description="when it went online/offline")
    manifest: Manifest | None = None


class StateSnapshot(Strict):
    protocol: int = PROTOCOL_VERSION
    server_id: str = Field(description="changes when the server restarts")
    revision: int
    mission: Mission
    library: Library
    robots: dict[Name, RobotInfo] = Field(default_factory=dict)


class FleetEvent(Strict):
    robot: RobotInfo


class Alert(Strict):
    level: Literal["info", "warning", "error"] = "warning"
    kind: str = Field(
        "",
        description="what happened: failure | offline | reconcile | report_refused | journal "
        "(the server cannot write its journal) ('' from older servers); "
        "consoles merge their own alerts of the same kind",
    )
    robot: str | None = None
    skill: str | None = None
    message: str
    at: datetime


# -- robots -> server -------------------------------------------------------------


class QueueEntry(Strict):
    id: SkillId
    status: Status


class Register(Strict):
    manifest: Manifest
    queue: list[QueueEntry] = Field(
        default_factory=list, description="the robot's own synchronized queue (active first)"
    )
    reports: list[Report] = Field(default_factory=list, description="reports not yet acknowledged")


class RegisterReply(Strict):
    accepted: bool = True
    reason: str = ""
    last_seq: int = 0
    # skills the server holds as synchronized to this robot that the robot
    # does not know (it restarted): the robot may ask to have them again
    missing: list[SkillId] = Field(
        default_factory=list,
        description="skills the server held as synchronized to this robot that its queue lacks: "
        "returned to the plan",
    )


class ReportBatch(Strict):
    reports: list[Report]


class ReportAck(Strict):
    last_seq: int
    refused: list[ErrorReply] = Field(default_factory=list)


class Telemetry(Strict):
    robot: Name
    pose: Pose = Field(default_factory=Pose)
    battery: float = Field(1.0, ge=0.0, le=1.0)
    link: float = Field(1.0, ge=0.0, le=1.0, description="link quality 0..1")
    in_range: bool = True
    mode: str = "idle"
    skill: SkillId | None = None
    progress: float | None = Field(None, ge=0.0, le=1.0)
    eta_s: float | None = None
    info: str = ""
    at: datetime


# -- server -> robot ------------------------------------------------------------------


class Enqueue(Strict):
    cmd: Literal["enqueue"] = "enqueue"
    skills: list[SkillInstance]
    # skill id -> partners (robot, skill id) it must wait for at a barrier
    barriers: dict[SkillId, BarrierInfo] = Field(default_factory=dict)
    front: bool = Field(False, description="put before the rest of the queue (retries)")


class BarrierInfo(Strict):
    barrier: Name
    partners: dict[Name, SkillId]


class Dequeue(Strict):
    cmd: Literal["dequeue"] = "dequeue"
    ids: list[SkillId]


class Run(Strict):
    cmd: Literal["run"] = "run"


class Pause(Strict):
    cmd: Literal["pause"] = "pause"


class Stop(Strict):
    cmd: Literal["stop"] = "stop"


class Reset(Strict):
    cmd: Literal["reset"] = "reset"


Command = Annotated[Enqueue | Dequeue | Run | Pause | Stop | Reset, Field(discriminator="cmd")]


class CommandReply(Strict):
    ok: bool = True
    reason: str = ""
    ids: list[SkillId] = Field(default_factory=list, description="enqueued or removed skills")
    kept: list[SkillId] = Field(
        default_factory=list, description="asked to remove but already started"
    )
    # reports made before answering, so the server sees them first
    reports: list[Report] = Field(default_factory=list)


# -- robot <-> robot ------------------------------------------------------------------


class WorldMessage(Strict):
    kind: Literal["ask", "tell"]
    sender: Name
    topic: str = Field(description="e.g. 'stone', 'box', 'rss'")
    data: dict[str, Any] = Field(default_factory=dict)


class WorldReply(Strict):
    known: bool = True
    data: dict[str, Any] = Field(default_factory=dict)


Enqueue.model_rebuild()


def dumps(model: Strict) -> bytes:
    return model.model_dump_json(exclude_none=False).encode()


def first_error(e: ValidationError) -> str:
    """What is wrong with a message, for a person: "field.path: message"."""
    first = e.errors()[0]
    where = ".".join(str(x) for x in first["loc"])
    return f"{where}: {first['msg']}" if where else first["msg"]


def event_batch_bytes(batch: EventBatch) -> bytes:
    # events are small: leave out defaults that replay restores anyway
    return batch.model_dump_json().encode()
