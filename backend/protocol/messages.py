"""The wire protocol's messages (JSON from these models); the key space is in `keys`.

Documented for third parties in docs/protocol.md (generated sections come
from these models). Bump PROTOCOL_VERSION on any incompatible change.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal

from pydantic import AwareDatetime, Field, ValidationError

from backend.core.alerts import AlertKind, RaisedAlert
from backend.core.contact import Contact
from backend.core.events import EventBatch
from backend.core.library import Library, SkillSignature
from backend.core.model import (
    AskRef,
    BarrierInfo,
    Dequeue,
    Enqueue,
    Mission,
    Name,
    Pause,
    Pose,
    QuestionAnswer,
    Reset,
    RobotCommand,
    Run,
    SkillId,
    Stop,
    Strict,
)
from backend.core.ops import Answer, Ask, AskEnded, DownlinkMessage, OperatorOp, QueueEntry, Report
from backend.core.verification import Verification
from backend.protocol.keys import PROTOCOL_VERSION

# the robot-facing models live in core (the uplink is part of the mission);
# they are protocol messages too
__all__ = [
    "AlertKind",
    "Answer",
    "Ask",
    "AskEnded",
    "BarrierInfo",
    "Dequeue",
    "DownlinkMessage",
    "Enqueue",
    "Pause",
    "QuestionAnswer",
    "QueueEntry",
    "Report",
    "Reset",
    "RobotCommand",
    "Run",
    "Stop",
]

# a robot agent's run: letters, digits, '_' and '-'
Session = Annotated[str, Field(pattern=r"^[A-Za-z0-9_\-]+$", min_length=1, max_length=64)]
MAX_BATCH = 1000  # messages or commands in one Uplink, Downlink or Register

ALERTS_KEPT = 100  # the server's latest alerts in a state snapshot
MAX_HISTORY = 10_000  # journal entries in one HistoryReply

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
    seq: int | None = Field(
        None, description="in `DownlinkAck.refused`: the downlink seq of the refused message"
    )


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


class HistoryRequest(Strict):
    """Who did what, from the server's journal (`ctl history`): the newest
    `limit` batches matching every filter given, oldest first."""

    robot: Name | None = Field(None, description="only changes concerning this robot")
    user: str | None = Field(
        None, max_length=200, description="only operations of this user (the login or --user)"
    )
    since: datetime | None = Field(None, description="only changes journaled at or after this")
    limit: int = Field(200, ge=1, le=MAX_HISTORY)


class HistoryEntry(Strict):
    revision: int
    at: datetime = Field(description="when the server journaled it (the ground's clock)")
    actor: str = Field(description="'user@client', a client id, or the robot for its reports")
    user: str = ""
    client: str = ""
    op: str = Field(description="the operation's name: add, sync, report, answer, uplink_sent...")
    robots: list[Name] = Field(default_factory=list, description="the robots it concerns")
    batch: EventBatch = Field(description="what it changed")


class HistoryReply(Strict):
    entries: list[HistoryEntry] = Field(default_factory=list, max_length=MAX_HISTORY)
    more: bool = Field(False, description="older matching changes were left out (`limit`, size)")


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


MissionClock = Literal["sim", "wall"]


class RobotContact(Contact):
    """A robot's contact state as the server computes it, with the mission
    clock its times are on: `sim` (seconds since the simulator started) or
    `wall` (POSIX seconds, UTC)."""

    clock: MissionClock = Field(
        "wall", description="the clock of next_contact and closes: sim or wall"
    )
    source: Literal["none", "file", "sim"] = Field(
        "none",
        description="where its windows come from: none (always in contact), the server's "
        "--contact-windows file, or the simulator's --comms-window",
    )


class RobotInfo(Strict):
    """The server's view of a robot: presence, manifest and its link."""

    name: Name
    online: bool = False
    since: datetime | None = Field(None, description="when it went online/offline")
    manifest: Manifest | None = None
    session: str | None = Field(None, description="the registered run of its agent (the owner)")
    heard: datetime | None = Field(
        None,
        description="when the server last heard from it (registration, downlink); published "
        "at least every 10 s while it talks",
    )
    delay_s: float | None = Field(
        None,
        ge=0,
        description="estimated one-way delay robot -> ground, from the `sent` times of its "
        "messages (assumes synchronized clocks)",
    )
    contact: RobotContact | None = Field(
        None, description="in contact, out of contact (next contact at T) or offline"
    )
    verification: list[Verification] = Field(
        default_factory=list,
        max_length=200,
        description="its commands under way (pending, or applied with skills not ended): "
        "each one's stages queued, sent, received, started, completed, with due times",
    )
    joining: bool = Field(
        False,
        description="it registered under a name the mission lacks, with a type the library "
        "knows (`manifest`): an operator may add it (operation `robot_add`)",
    )


class Alert(RaisedAlert):
    """An alert the server raised: published on the alerts key, and the last
    `ALERTS_KEPT` of them are in every `StateSnapshot` (a console that was away
    sees what it missed)."""

    id: int = Field(ge=1, description="numbered from 1 per server run (`StateSnapshot.server_id`)")
    at: datetime


class StateSnapshot(Strict):
    protocol: int = PROTOCOL_VERSION
    server_id: str = Field(description="changes when the server restarts")
    revision: int
    mission: Mission
    library: Library
    robots: dict[Name, RobotInfo] = Field(default_factory=dict)
    alerts: list[Alert] = Field(
        default_factory=list,
        max_length=ALERTS_KEPT,
        description=f"the server's last {ALERTS_KEPT} alerts of this run, oldest first",
    )


class FleetEvent(Strict):
    robot: RobotInfo


# -- robots -> server -------------------------------------------------------------


class Register(Strict):
    """A robot agent's registration: who it is, what it holds, what it has
    not delivered yet."""

    manifest: Manifest
    session: Session = Field(description="this run of the agent: fresh at every start")
    queue: list[QueueEntry] = Field(
        default_factory=list,
        max_length=10_000,
        description="the robot's own synchronized queue (active first)",
    )
    downlink: list[DownlinkMessage] = Field(
        default_factory=list,
        max_length=MAX_BATCH,
        description="its downlink messages not acknowledged yet, in seq order",
    )
    last_seq: int = Field(0, ge=0, description="the last downlink seq it has made")
    uplink_applied: int = Field(0, ge=0, description="the last uplink seq it has processed")
    sent: AwareDatetime | None = Field(
        None, description="when it left the robot (robot's clock, with its zone)"
    )
    asking: list[AskRef] | None = Field(
        None,
        max_length=1000,
        description="the refs of the questions its skills still ask (None: it does not say): "
        "the mission's other open questions of this robot are withdrawn",
    )


# why a registration was not accepted (stable)
RegisterCode = Literal[
    "", "protocol", "unknown_robot", "unknown_type", "joining", "wrong_type", "taken"
]


class RegisterReply(Strict):
    accepted: bool = True
    code: RegisterCode = Field("", description="why it was not accepted (stable)")
    reason: str = ""
    last_seq: int = Field(
        0, description="the ground applied (or refused) its downlink up to here: drop those"
    )
    refused: list[ErrorReply] = Field(
        default_factory=list,
        description="messages of its `downlink` applied as refused (consumed, alerted), each "
        "with its seq: do not send them again",
    )
    missing: list[SkillId] = Field(
        default_factory=list,
        description="skills the server held as synchronized to this robot that its queue lacks: "
        "returned to the plan",
    )
    adopted: list[SkillId] = Field(
        default_factory=list,
        description="skills it holds that the mission had as unsynchronized: synchronized again",
    )
    dropped: list[SkillId] = Field(
        default_factory=list,
        description="skills it holds that the mission does not give it: a command asks it to "
        "drop them",
    )
    heartbeat_s: float = Field(5.0, description="send a Downlink at least this often")
    outcomes: dict[SkillId, Literal["success", "failure"]] = Field(
        default_factory=dict,
        max_length=10_000,
        exclude_if=lambda v: not v,  # left out while empty: older robots read the reply
        description="how this robot's finished skills ended that a skill of another robot "
        "waits for (policies.after): answer them to partners (a restarted robot forgot)",
    )
    skills: dict[Name, SkillSignature] = Field(
        default_factory=dict,
        description="the library's signature of each skill the manifest offers that the robot's "
        "type has: check the handlers against it; a skill the robot runs on its own (a "
        "recharge before a skill) is called with its `defaults`",
    )


class Downlink(Strict):
    """Robot -> ground: its reports and answers, one contiguous sequence."""

    robot: Name
    session: Session
    messages: list[DownlinkMessage] = Field(
        default_factory=list,
        max_length=MAX_BATCH,
        description="not acknowledged yet, oldest first (empty: a heartbeat)",
    )
    uplink_applied: int = Field(0, ge=0, description="the last uplink seq it has processed")
    sent: AwareDatetime = Field(description="when it left the robot (robot's clock, with its zone)")


class DownlinkAck(Strict):
    last_seq: int = Field(description="every message up to this seq is applied: drop them")
    missing: list[int] = Field(
        default_factory=list,
        description="[first, last] seqs missing before what was sent: send from last_seq + 1",
    )
    refused: list[ErrorReply] = Field(
        default_factory=list, description="messages applied as refused (consumed, alerted)"
    )


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
    at: AwareDatetime


# -- server -> robot ------------------------------------------------------------------


class UplinkEntry(Strict):
    """One command as the robot gets it."""

    seq: int = Field(ge=1, description="apply once, in this order")
    id: int = Field(ge=1, description="the command number the operator sees")
    expires: AwareDatetime | None = Field(None, description="never apply it after this")
    cancel: bool = Field(False, description="withdrawn: answer `cancelled` if not applied yet")
    command: RobotCommand


class Uplink(Strict):
    """Ground -> robot: every pending command of its uplink, in seq order."""

    robot: Name
    session: Session = Field(description="the registered session it is for")
    commands: list[UplinkEntry] = Field(max_length=MAX_BATCH)
    downlink_ack: int = Field(0, description="the ground applied its downlink up to here")
    sent: AwareDatetime


class UplinkReceipt(Strict):
    """The robot got the Uplink (not: applied it; its answers come on the downlink)."""

    session: Session
    applied: int = Field(0, ge=0, description="the last uplink seq it has processed")


# -- robot <-> robot ------------------------------------------------------------------


class WorldMessage(Strict):
    kind: Literal["ask", "tell"]
    sender: Name
    topic: str = Field(description="e.g. 'stone', 'box', 'rss'")
    data: dict[str, Any] = Field(default_factory=dict)


class WorldReply(Strict):
    known: bool = True
    data: dict[str, Any] = Field(default_factory=dict)


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
