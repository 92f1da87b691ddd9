"""Writes docs/protocol.md (prose, tables, a worked trace) and the JSON
Schemas of every message in docs/protocol/*.json, all generated from the
protocol models, so the document cannot drift from the code (a test checks
both are up to date).

    python -m backend.protocol.doc            # writes docs/protocol.md and docs/protocol/
    python -m backend.protocol.doc --check    # exit 1 if they are stale
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any, get_args

from pydantic import TypeAdapter

from backend.core.alerts import LOW_BATTERY, MEANING, AlertKind
from backend.core.events import (
    CommandChanged,
    CommandQueued,
    Event,
    EventBatch,
    SkillAdded,
    SkillStatusChanged,
)
from backend.core.events import ReportSeq as ReportSeqEvent
from backend.core.limits import LIMITS, MiB
from backend.core.model import (
    CHECK_ID_PATTERN,
    KEEP_SETTLED,
    MAX_CHOICE,
    MAX_CHOICES,
    MAX_QUESTION_TEXT,
    Enqueue,
    ParamType,
    Run,
    SkillInstance,
    Status,
    UplinkCommand,
)
from backend.core.ops import AddSkill, Answer, Ask, AskEnded, Control, OperatorOp, Report, Sync
from backend.core.plan.checks import RULES as CHECK_RULES
from backend.protocol import mapfeed as mf
from backend.protocol import messages as p
from backend.protocol import timing as tm
from backend.protocol import values as v
from backend.protocol.keys import PROTOCOL_VERSION, Keys
from backend.protocol.messages import ALERTS_KEPT

ROOT = Path(__file__).resolve().parents[2]
SCHEMA_DIR = "protocol"  # beside protocol.md

# the key space: (key, kind, who declares, payload)
KEY_SPACE: list[tuple[str, str, str, str]] = [
    (f"`{Keys.SERVER_ALIVE}`", "liveliness token", "server", "—"),
    (f"`{Keys.OP}`", "queryable", "server", "`Request` → `OpReply` / `ErrorReply`"),
    (
        f"`{Keys.op_as('USER')}`",
        "queryable",
        "server",
        "the same, from a logged-in user (`Request.user` is replaced by `USER`)",
    ),
    (
        f"`{Keys.account('USER')}`",
        "queryable",
        "server",
        "anything → `AccountInfo` (role of a logged-in user)",
    ),
    (
        f"`{Keys.STATE}`",
        "queryable",
        "server",
        "`StateRequest` (or nothing) → `StateSnapshot`; anything else: `bad_request`",
    ),
    (
        f"`{Keys.HISTORY}`",
        "queryable",
        "server",
        "`HistoryRequest` (or nothing) → `HistoryReply`: who did what, from the journal",
    ),
    (
        f"`{Keys.EVENTS}`",
        "publication",
        "server",
        "`EventBatch`, or a JSON array of them (revisions consecutive)",
    ),
    (f"`{Keys.FLEET}`", "publication", "server", "`FleetEvent` (presence, manifest, link)"),
    (f"`{Keys.ALERTS}`", "publication", "server", "`Alert`"),
    (
        f"`{Keys.PING}`",
        "queryable",
        "server",
        "anything → `pong` (raw-transport baseline of the benchmarks)",
    ),
    (f"`{Keys.register('ROBOT')}`", "queryable", "server", "`Register` → `RegisterReply`"),
    (f"`{Keys.downlink('ROBOT')}`", "queryable", "server", "`Downlink` → `DownlinkAck`"),
    (
        f"`{Keys.alive('ROBOT', 'SESSION')}`",
        "liveliness token",
        "robot",
        "— (SESSION: the run of the agent that registered)",
    ),
    (
        f"`{Keys.uplink('ROBOT')}`",
        "queryable",
        "robot",
        "`Uplink` → `UplinkReceipt` / `ErrorReply`",
    ),
    (f"`{Keys.telemetry('ROBOT')}`", "publication", "robot", "`Telemetry`"),
    (f"`{Keys.world('ROBOT')}`", "queryable", "robot", "`WorldMessage` → `WorldReply`"),
    (
        f"`{Keys.barrier_ready('BARRIER', 'ROBOT')}`",
        "liveliness token",
        "robot",
        "— (present while at a barrier, see Barriers)",
    ),
    (f"`{mf.KEY_MAP_SNAPSHOT}`", "queryable", "simulator", "anything → `MapSnapshot`"),
    (
        f"`{mf.KEY_MAP_DELTA}`",
        "publication",
        "simulator",
        "`MapDelta` (`seq` consecutive, at most ~2 Hz)",
    ),
    (f"`{mf.KEY_STATUS}`", "queryable", "simulator", "anything → `SimStatus`"),
    (
        f"`{mf.KEY_STATUS_LIVE}`",
        "publication",
        "simulator",
        "`StatusUpdate`: the full status or a patch (on change, at least every 10 s)",
    ),
]

# the status changes robots may report: (from, to)
REPORTED_TRANSITIONS: list[tuple[str, str]] = [
    ("`idle_synchronized`", "`synchwaiting`, `running`, `failure`"),
    ("`synchwaiting`", "`running`, `idle_synchronized` (stopped), `failure`, itself with new info"),
    (
        "`running`",
        (
            "`paused`, `success`, `failure`, `idle_synchronized` (stopped), "
            "itself with a higher `attempt` (autonomous retry)"
        ),
    ),
    ("`paused`", "`running`, `idle_synchronized` (stopped), `failure`"),
    ("`success`, `failure`", "nothing: they are the execution log"),
]

# the robot's mode (Telemetry.mode): (mode, what it means, command -> next mode)
MODES: list[tuple[str, str, str]] = [
    ("`idle`", "nothing held, halted", "`enqueue` → `halted`; `run` → run mode, stays `idle`"),
    (
        "`halted`",
        "skills queued, not executing (the start, and after pause/stop/reset/failure)",
        "`run` → `starting`; `reset` → `idle`",
    ),
    (
        "`starting`",
        "run mode: the head of the queue was taken, its first report not made yet",
        "→ `running` or `synchwaiting` (barrier) by itself",
    ),
    (
        "`synchwaiting`",
        "at a barrier, waiting for partners",
        "all ready → `running`; `stop` → `halted` (skill back at the head); `pause` refused",
    ),
    (
        "`running`",
        "executing the active skill; in run mode it goes on with the next",
        "`pause` → `paused`; `stop` → `halted`; `reset` → `idle`; "
        "success → next skill (`starting`) or `idle`; failure → `halted`",
    ),
    (
        "`paused`",
        "the active skill holds at its next checkpoint",
        "`run` → `running`; `stop` → `halted`; `reset` → `idle`",
    ),
]

# every refusal code: (code, where it comes from, meaning and what to do)
ERROR_CODES: list[tuple[str, str, str]] = [
    (
        "bad_request",
        "server, robot",
        "a request (a world message) that cannot be read: the field is named",
    ),
    ("read_only", "server, clients", "an observer account (or a role without the operation key)"),
    ("stale", "server", "what the operation touches changed after `expected_revision`: reload"),
    ("journal_failed", "server", "the journal cannot be written: nothing changed; send it again"),
    ("unknown_robot", "server", "no such robot in the mission"),
    ("unknown_skill", "server", "no skill with that id"),
    ("unknown_skill_type", "server", "the robot's type offers no such skill"),
    ("bad_param", "server", "a parameter does not fit the library (named in `param`)"),
    (
        "bad_contingency",
        "server",
        "a fallback skill the robot does not have or whose parameters do not fit, a goto to no "
        "marker or for a robot without a drive skill (policies on_failure / on_timeout)",
    ),
    ("bad_index", "server", "a position outside the unsynchronized section"),
    ("exists", "server", "an id or name in use already"),
    ("not_idle", "server", "only idle (unsynchronized) skills can change"),
    ("locked", "server", "a pending command concerns it (uplinking, being unsynchronized)"),
    ("wrong_robot", "server", "the skill belongs to another robot"),
    ("nothing_to_sync", "server", "no idle skill left to synchronize"),
    ("nothing_to_unsync", "server", "no queued skill to take back"),
    ("not_queued", "server", "only queued (idle_synchronized) skills can be unsynchronized"),
    ("not_applicable", "server", "run/pause/stop/reset does not apply to the robot now (why)"),
    ("cannot_retry", "server", "not a failed skill, retried already, or the robot moved on"),
    ("incompatible", "server", "the robot's manifest lacks the skill or its major version"),
    ("plan_errors", "server", "sync: unwaived plan check errors name skills it would send"),
    ("unknown_check", "server", "waive: no plan check of that name"),
    ("unknown_waiver", "server", "unwaive: no waiver for that check"),
    ("unknown_command", "server", "cancel: no such command number"),
    ("not_pending", "server", "cancel: the command is settled already"),
    (
        "cannot_undo",
        "server",
        "undo of a sync that was sent or answered already: cancel it (sent) or unsync",
    ),
    ("nothing_to_undo", "server", "no edit of yours left to undo"),
    ("nothing_to_redo", "server", "nothing undone to redo"),
    ("barrier_invalid", "server", "a barrier needs idle skills of at least two robots"),
    ("barrier_partner_synchronized", "server", "a partner skill is synchronized already"),
    ("unknown_barrier", "server", "no such barrier"),
    ("unknown_marker", "server", "no such marker"),
    ("bad_marker", "server", "a marker value of the wrong kind"),
    ("marker_in_use", "server", "a synchronized skill still uses the marker"),
    ("robot_exists", "server", "robot_add: the mission has a robot of that name"),
    ("unknown_robot_type", "server", "robot_add: the library has no such robot type"),
    ("retired", "server", "the robot is retired: no new syncs, nothing given to it"),
    ("nothing_to_reassign", "server", "reassign: no skill named, or the robot's plan is empty"),
    ("cannot_reassign", "server", "reassign: no skill named can go to the robot (each says why)"),
    ("unknown_question", "server", "answer_question: no question of that number"),
    ("bad_choice", "server", "answer_question: a choice the question does not offer"),
    (
        "already_answered",
        "server",
        "answer_question: an answer is on its way (its command pending) or taken: cancel it first",
    ),
    ("question_closed", "server", "answer_question: the robot ended the question already"),
    ("too_late", "server", "answer_question: its default applied on board (past its due)"),
    ("bad_mission", "server", "load: the mission does not validate"),
    ("robot_busy", "server", "load/new while commands are pending (or a direct-path command)"),
    ("robots_busy", "server", "load/new while robots hold synchronized skills: reset them"),
    (
        "robots_online",
        "server",
        "load with `keep_state` while a robot of the mission is online: load it as a plan",
    ),
    ("unknown_account", "server", "account query for a user the server does not know"),
    ("limit_exceeded", "server, robot", "a message over a limit (see Limits): nothing applied"),
    ("not_replayable", "server", "a change the journal could not read back as it is: refused"),
    (
        "bad_message",
        "server, robot",
        "a message that cannot be read (the field is named), or a robot's naming another robot",
    ),
    ("bad_register", "server", "a registration on another robot's key"),
    (
        "not_registered",
        "server",
        "a downlink from a session that is not registered, or after a load: register",
    ),
    (
        "bad_report",
        "server",
        "a report or answer the rules refuse, whatever is wrong with it (in "
        "`DownlinkAck.refused` / `RegisterReply.refused`, with its `seq`)",
    ),
    ("protocol_mismatch", "server, clients", "the other side speaks another protocol version"),
    ("unreachable", "robot", "out of communication range: the Uplink did not reach it"),
    ("wrong_session", "robot", "an Uplink for another run of the robot: register first"),
    ("robot_error", "robot", "a world ask/tell the robot's handler failed on"),
    ("server_error", "clients", "an error reply that is not an ErrorReply"),
]

# RegisterReply.code
REGISTER_CODES: list[tuple[str, str]] = [
    ("protocol", "the manifest's `protocol` is not this server's"),
    ("unknown_robot", "the mission has no robot of that name (no longer sent: see `joining`)"),
    ("unknown_type", "a new name with a type the library lacks: the reason says what is missing"),
    (
        "joining",
        "a new name with a type the library knows: announced to the operators; register "
        "again (every few seconds) until one adds the robot (`robot_add`)",
    ),
    ("wrong_type", "the mission gives that robot another type"),
    ("taken", "another session holds the name and is online: stand down, ask again later"),
]

# fields a robot must get right: (message.field, rule)
FIELD_RULES: list[tuple[str, str]] = [
    (
        "`Register.session`",
        "fresh at every start of the robot's software; the same for its "
        "presence token and every Downlink of that run",
    ),
    (
        "`Register.queue`",
        "what the robot holds, the active skill first; `skill` and `params` "
        "let the ground tell its copy from another skill of the same id",
    ),
    ("`Register.downlink`", "every Report/Answer not acknowledged yet, in seq order"),
    ("`Register.last_seq`", "the last downlink seq the robot has made (0: none)"),
    ("`Register.uplink_applied`", "the last uplink seq the robot has processed (0: none)"),
    (
        "`Register.sent`, `Downlink.sent`",
        "when the message left the robot, its clock, with its zone (a time without one is "
        "refused `bad_message` naming the field); the ground estimates the one-way delay "
        "from it (clocks must agree: NTP, spacecraft time)",
    ),
    (
        "`RegisterReply.last_seq`",
        "the ground applied (or refused) the downlink up to here, exactly as far as it "
        "has: drop those; if it is higher than the robot's own last seq (a restart), number "
        "on after it",
    ),
    (
        "`Manifest.skills`",
        "skill name -> the version it implements (SemVer); a sync or retry of a skill it "
        "lacks, or whose major version differs from the library's, is refused on the ground "
        "(`incompatible`); minor and patch versions may differ",
    ),
    (
        "`Downlink.messages`",
        "the unacknowledged messages from the oldest, at most 1000; `seq` "
        "consecutive: 1, 2, 3, ... per robot, one sequence for reports and answers",
    ),
    (
        "`Downlink.uplink_applied`",
        "the last uplink seq processed: the ground sends again what the robot has not processed",
    ),
    ("`DownlinkAck.last_seq`", "cumulative: drop every message up to it"),
    (
        "`DownlinkAck.missing`",
        "[first, last] seqs the ground has not got before what you sent: "
        "send again from `last_seq` + 1",
    ),
    (
        "`DownlinkAck.refused`, `RegisterReply.refused`",
        "the messages of this Downlink (Register) consumed as refused, alerted: one "
        "`ErrorReply` each, its `seq` the message's; do not send them again (a message "
        "refused before and sent again is skipped, not listed again)",
    ),
    ("`Report.seq`", "the next downlink number; never reused"),
    ("`Report.status`", "the new status, per the transition table"),
    (
        "`Report.attempt`",
        "the skill's attempt: 1, `N` for a retry `ID.N` the operator queued, + 1 for each "
        "autonomous retry (`running` again); never lower than before",
    ),
    (
        "`Report.at`, `Answer.at`",
        "when the change happened, the robot's clock with its zone (the first `running` "
        "sets `started_at`, `success`/`failure` set `finished_at`)",
    ),
    ("`Answer.command`", "the uplink `seq` of the command answered (not its `id`)"),
    (
        "`Answer.outcome`",
        "`applied`, `refused` (with `reason`), `expired` (processed after "
        "`expires`), `cancelled` (`cancel` was set when it was processed)",
    ),
    (
        "`Answer.queued`",
        "enqueue: the ids the robot holds now (a subset of those sent; "
        "ids it ran already are left out)",
    ),
    (
        "`Answer.removed`",
        "dequeue/reset: the ids it removed; `kept`: asked to remove, but started or finished: kept",
    ),
    (
        "`Uplink.commands`",
        "every pending command, in seq order; seqs may skip numbers (a "
        "command withdrawn before it was ever sent)",
    ),
    (
        "`UplinkEntry.seq`",
        "process each once: ignore seq ≤ your last processed one; transmissions may "
        "overlap (each carries every pending command), process whichever arrives first",
    ),
    ("`UplinkEntry.expires`", "past it, answer `expired` instead of applying"),
    ("`UplinkEntry.cancel`", "set: answer `cancelled` instead of applying"),
    ("`Uplink.downlink_ack`", "same as `DownlinkAck.last_seq`: drop those messages"),
    ("`UplinkReceipt.session`", "your session: the ground counts only its registered one's"),
]


# how a mirror applies each event (`ev`): (event, its fields, what to do). Every
# kind of the protocol's Event union is here (a test checks it).
EVENT_RULES: list[tuple[str, str, str]] = [
    (
        "`skill_added`",
        "robot, index, skill",
        "insert `skill` into `tasks[robot]` at `index`, which counts the robot's whole list "
        "(log, active, queued, plan; `AddSkill.at` and `MoveSkill.index` count only the "
        "unsynchronized section); its `rev` = the revision; `task_revs[robot]` = the revision; "
        "`next_skill` = max(`next_skill`, N + 1) for an id ending in `-N`",
    ),
    ("`skill_removed`", "robot, id", "remove it; `task_revs[robot]` = the revision"),
    (
        "`skill_moved`",
        "robot, id, index",
        "take it out, then insert it at `index` (whole list, counted without it); "
        "`task_revs[robot]` = the revision",
    ),
    (
        "`skill_status`",
        "id, status, info, attempt, at",
        "its execution moved on: set `status` (absent only in old journals); `info` and "
        "`attempt` when given; `at` with the first `running` sets `started_at`, with "
        "`success`/`failure` sets `finished_at`, back to `idle` or `idle_synchronized` clears "
        "`started_at`; its `rev` = the revision",
    ),
    (
        "`skill_edited`",
        "id, label, params, bindings, policies",
        "set each field given (absent: keep it); its `rev` = the revision",
    ),
    (
        "`barrier_set`",
        "id, barrier",
        "set (add or replace) `barriers[id]`; `next_barrier` = max(`next_barrier`, N + 1) "
        "for an id `bN`",
    ),
    ("`barrier_removed`", "id", "remove `barriers[id]`"),
    ("`marker_set`", "name, marker", "set `markers[name]`; `marker_revs[name]` = the revision"),
    ("`marker_removed`", "name", "remove `markers[name]` and `marker_revs[name]`"),
    ("`report_seq`", "robot, seq", "`report_seqs[robot]` = `seq`"),
    (
        "`command_queued`",
        "command",
        "append it to `uplink[command.robot]`; `next_command` = max(`next_command`, id + 1); "
        "`uplink_seqs[robot]` = max(`uplink_seqs[robot]`, seq)",
    ),
    (
        "`command_changed`",
        "id, state, sent, settled, answered, cancel_requested, reason, done, kept",
        "set each field given on that command (absent: keep it; none is ever cleared); "
        "when it is settled after it (not `queued` nor "
        f"`sent`), keep in its robot's list the pending commands and only the last "
        f"{KEEP_SETTLED} settled ones (list order): drop the older settled ones",
    ),
    (
        "`waiver_set`",
        "check, waiver",
        "set `waivers[check]`, its `revision` = the revision",
    ),
    ("`waiver_removed`", "check", "remove `waivers[check]`"),
    (
        "`robot_added`",
        "name, spec",
        "set `robots[name]` = spec; `tasks[name]` = [] unless it exists; "
        "`task_revs[name]` = the revision",
    ),
    (
        "`robot_retired`",
        "name, reason",
        "set `robots[name].retired` = reason; `task_revs[name]` = the revision",
    ),
    (
        "`question_asked`",
        "question",
        "append it to `questions[question.robot]`; `next_question` = max(`next_question`, id + 1)",
    ),
    (
        "`question_answered`",
        "id, choice, by, at, command",
        "on that question set `answer` = choice, `answered_by` = by, `answered_at` = at, "
        "`command`; it stays `open`",
    ),
    (
        "`question_closed`",
        "id, state, choice, at, reason",
        "on that question set `state`, `choice`, `closed` = at, `reason`; keep in its robot's "
        f"list the open questions and only the last {KEEP_SETTLED} closed ones",
    ),
    ("`mission_replaced`", "mission", "replace the whole mission with `mission`"),
]

# the robot's side of awkward commands: (case, what it does and answers)
ROBOT_CASES: list[tuple[str, str]] = [
    (
        "`enqueue` with `front` while a skill is active",
        "the new skills go before the queued ones, after the active one, which goes on",
    ),
    (
        "`enqueue` of an id it holds (a command sent again)",
        "not queued twice; `queued` lists it again",
    ),
    ("`enqueue` of an id it finished", "never queued nor run again; left out of `queued`"),
    (
        "`enqueue` of a skill it has no handler for",
        "the whole command is `refused`, the `reason` naming the skill",
    ),
    ("`dequeue` of an id it never held", "nothing to do; `removed` lists it"),
    ("`dequeue` of an id it started or finished", "kept; `kept` lists it"),
    (
        "`pause` with nothing running",
        "leaves run mode; `applied`, with a `reason` saying nothing was running",
    ),
    ("`pause` at a barrier (`synchwaiting`)", "`refused`: stop it instead"),
    (
        "`stop` or `reset` with nothing active",
        "leaves run mode; `applied` (a reset removes what is queued)",
    ),
    (
        "`run` with nothing queued",
        "run mode; `applied` with a `reason`; what is synchronized next starts at once",
    ),
    (
        "a retry `ID.N` the operator queued",
        "an ordinary skill with its own id, reported with `attempt` N",
    ),
    (
        "an autonomous retry (`policies.retries`)",
        "the same id reports `running` again with `attempt` + 1; `failure` only after the last",
    ),
    (
        "running again at the same attempt (after recharging first, say)",
        "not reported: the ground refuses it (`bad_report`)",
    ),
    (
        "`answer` to a question it no longer asks (its default applied, its skill ended)",
        "`refused`, the `reason` saying how the question ended",
    ),
    (
        "`answer` with a choice the question does not offer",
        "`refused`; the question stays open",
    ),
]

# which operation may be refused with which code (beyond the codes of every request:
# bad_request, read_only, stale, journal_failed, limit_exceeded, not_replayable)
OP_CODES: list[tuple[str, str]] = [
    ("add", "unknown_robot, unknown_skill_type, bad_param, bad_index, locked"),
    ("delete", "unknown_skill, not_idle, locked, barrier_partner_synchronized"),
    ("move", "unknown_skill, not_idle, locked, bad_index"),
    ("edit", "unknown_skill, not_idle, locked, bad_param"),
    ("retry_edit", "unknown_skill, cannot_retry, locked, bad_param"),
    (
        "sync",
        "unknown_robot, unknown_skill, wrong_robot, not_idle, locked, nothing_to_sync, "
        "bad_param, plan_errors, incompatible",
    ),
    ("unsync", "unknown_robot, unknown_skill, wrong_robot, not_queued, locked, nothing_to_unsync"),
    ("run, pause, stop, reset", "unknown_robot, not_applicable"),
    ("retry", "unknown_skill, cannot_retry, incompatible"),
    ("cancel", "unknown_command, not_pending, cannot_undo (the undo of a sync)"),
    ("barrier", "unknown_skill, not_idle, locked, barrier_invalid"),
    ("unbarrier", "unknown_barrier, not_idle, locked"),
    ("barrier_edit", "unknown_barrier, not_idle, locked"),
    ("marker_add", "exists"),
    ("marker_move", "unknown_marker, bad_marker"),
    ("marker_rename", "unknown_marker, exists, marker_in_use"),
    ("marker_delete", "unknown_marker, marker_in_use"),
    ("waive", "unknown_check"),
    ("unwaive", "unknown_waiver"),
    ("robot_add", "robot_exists, unknown_robot_type"),
    ("robot_retire", "unknown_robot, retired"),
    ("reassign", "unknown_robot, unknown_skill, retired, nothing_to_reassign, cannot_reassign"),
    (
        "answer_question",
        "unknown_question, bad_choice, already_answered, question_closed, too_late",
    ),
    ("load", "bad_mission, robot_busy, robots_busy, robots_online"),
    ("new", "robot_busy, robots_busy"),
    ("undo, redo", "nothing_to_undo, nothing_to_redo, cannot_undo, and the reverted op's codes"),
]


def _check_names() -> str:
    return ", ".join(f"`{r.rule}`" for r in CHECK_RULES)


def _event_kinds() -> list[str]:
    """Every `ev` of the protocol's events."""
    union = Event.__origin__.__args__  # type: ignore[attr-defined]
    return [m.model_fields["ev"].default for m in union]


def _table(head: tuple[str, ...], rows: Sequence[tuple[str, ...]]) -> str:
    """A markdown table."""
    lines: list[tuple[str, ...]] = [head, tuple("---" for _ in head), *rows]
    return "".join("| " + " | ".join(cells) + " |\n" for cells in lines)


# -- the worked trace --------------------------------------------------------------

T0 = datetime(2030, 6, 1, 12, 0, 0, tzinfo=UTC)
D = 2.0  # one-way delay of the trace
SESSION = "a1b2c3d4e5f6"


def _t(seconds: float) -> datetime:
    return T0 + timedelta(seconds=seconds)


def _trace() -> list[tuple[float, str, str, Any]]:
    """(ground time, who -> who, key, message) of add -> sync -> run -> report."""
    goal = {"x": 12.0, "y": 3.0, "z": 0.0, "roll": 0.0, "pitch": 0.0, "yaw": 0.0}
    skill = SkillInstance(
        id="lru1-3", skill="drive_to", label="to the ridge", params={"goal": goal}
    )
    enqueue = Enqueue(skills=[skill])
    cmd1 = UplinkCommand(
        id=1, robot="lru1", seq=1, op="sync", command=enqueue, skills=["lru1-3"], created=_t(1)
    )
    cmd2 = UplinkCommand(id=2, robot="lru1", seq=2, op="run", command=Run(), created=_t(6))

    def up(*cmds: UplinkCommand, at: float, ack: int) -> p.Uplink:
        return p.Uplink(
            robot="lru1",
            session=SESSION,
            commands=[p.UplinkEntry(seq=c.seq, id=c.id, command=c.command) for c in cmds],
            downlink_ack=ack,
            sent=_t(at),
        )

    def down(*msgs: Any, at: float, applied: int) -> p.Downlink:
        return p.Downlink(
            robot="lru1", session=SESSION, messages=list(msgs), uplink_applied=applied, sent=_t(at)
        )

    def changed(cid: int, **changes: Any) -> CommandChanged:
        return CommandChanged.model_validate({"id": cid, **changes})

    answer1 = Answer(robot="lru1", seq=1, command=1, outcome="applied", queued=["lru1-3"], at=_t(3))
    answer2 = Answer(robot="lru1", seq=2, command=2, outcome="applied", at=_t(10))
    running = Report(robot="lru1", seq=3, id="lru1-3", status=Status.RUNNING, at=_t(10))
    success = Report(
        robot="lru1", seq=4, id="lru1-3", status=Status.SUCCESS, info="arrived", at=_t(40)
    )
    op = "console -> server"
    return [
        (
            0.0,
            op,
            Keys.OP,
            p.Request(
                client="console-1",
                request_id="r1",
                op=AddSkill(
                    robot="lru1", skill="drive_to", label="to the ridge", params={"goal": goal}
                ),
            ),
        ),
        (0.0, "server -> console", "(reply)", p.OpReply(revision=1, value={"id": "lru1-3"})),
        (
            0.0,
            "server -> all",
            Keys.EVENTS,
            EventBatch(
                revision=1,
                actor="console-1",
                op="add",
                events=[SkillAdded(robot="lru1", index=2, skill=skill)],
            ),
        ),
        (
            1.0,
            op,
            Keys.OP,
            p.Request(client="console-1", request_id="r2", op=Sync(robot="lru1", through="lru1-3")),
        ),
        (
            1.0,
            "server -> console",
            "(reply)",
            p.OpReply(
                revision=2,
                value=v.Queued(
                    command=1, robot="lru1", seq=1, state="queued", skills=["lru1-3"], expires=None
                ).model_dump(mode="json"),
            ),
        ),
        (
            1.0,
            "server -> all",
            Keys.EVENTS,
            EventBatch(
                revision=2, actor="console-1", op="sync", events=[CommandQueued(command=cmd1)]
            ),
        ),
        (1.0, "server -> robot", Keys.uplink("lru1"), up(cmd1, at=1.0, ack=0)),
        (5.0, "robot -> server", "(reply)", p.UplinkReceipt(session=SESSION, applied=1)),
        (
            5.0,
            "server -> all",
            Keys.EVENTS,
            EventBatch(
                revision=3,
                actor="server",
                op="uplink_sent",
                events=[changed(1, state="sent", sent=_t(1).isoformat())],
            ),
        ),
        (5.0, "robot -> server", Keys.downlink("lru1"), down(answer1, at=3.0, applied=1)),
        (5.0, "server -> robot", "(reply)", p.DownlinkAck(last_seq=1)),
        (
            5.0,
            "server -> all",
            Keys.EVENTS,
            EventBatch(
                revision=4,
                actor="lru1",
                op="answer",
                events=[
                    ReportSeqEvent(robot="lru1", seq=1),
                    SkillStatusChanged(id="lru1-3", status=Status.IDLE_SYNCHRONIZED),
                    changed(
                        1,
                        state="acked",
                        settled=_t(3).isoformat(),
                        answered=_t(3).isoformat(),
                        reason="",
                        done=["lru1-3"],
                    ),
                ],
            ),
        ),
        (
            6.0,
            op,
            Keys.OP,
            p.Request(client="console-1", request_id="r3", op=Control(op="run", robot="lru1")),
        ),
        (
            6.0,
            "server -> console",
            "(reply)",
            p.OpReply(
                revision=5,
                value=v.ControlQueued(robots={"lru1": "queued"}, commands={"lru1": 2}).model_dump(
                    mode="json"
                ),
            ),
        ),
        (6.0, "server -> robot", Keys.uplink("lru1"), up(cmd2, at=6.0, ack=1)),
        (
            12.0,
            "robot -> server",
            Keys.downlink("lru1"),
            down(answer2, running, at=10.0, applied=2),
        ),
        (12.0, "server -> robot", "(reply)", p.DownlinkAck(last_seq=3)),
        (42.0, "robot -> server", Keys.downlink("lru1"), down(success, at=40.0, applied=2)),
        (42.0, "server -> robot", "(reply)", p.DownlinkAck(last_seq=4)),
    ]


_TAGS = ("cmd", "ev", "op", "kind")  # discriminators: always shown


def _slim(full: Any, slim: Any) -> Any:
    """`slim` (defaults left out) with the discriminators of `full` put back."""
    if isinstance(full, dict) and isinstance(slim, dict):
        return {
            k: _slim(full[k], slim[k]) if k in slim else full[k]
            for k in full
            if k in slim or k in _TAGS
        }
    if isinstance(full, list) and isinstance(slim, list):
        return [_slim(f, s) for f, s in zip(full, slim, strict=True)]
    return slim


def _trace_text() -> str:
    out = []
    for at, who, key, msg in _trace():
        shown = _slim(
            msg.model_dump(mode="json"), msg.model_dump(mode="json", exclude_defaults=True)
        )
        data = json.dumps(shown, indent=1)
        out.append(f"**t = {at:g} s**, {who}, `{key}`: `{type(msg).__name__}`\n")
        out.append("```json\n" + data + "\n```\n")
    return "\n".join(out)


# -- the document --------------------------------------------------------------------

# title -> model (or union): each gets docs/protocol/<file>.json
SCHEMAS: list[tuple[str, str, Any]] = [
    ("Request", "Request", p.Request),
    ("OpReply", "OpReply", p.OpReply),
    ("ErrorReply", "ErrorReply", p.ErrorReply),
    ("StateRequest", "StateRequest", p.StateRequest),
    ("StateSnapshot", "StateSnapshot", p.StateSnapshot),
    ("AccountInfo", "AccountInfo", p.AccountInfo),
    ("HistoryRequest", "HistoryRequest", p.HistoryRequest),
    ("HistoryReply", "HistoryReply", p.HistoryReply),
    ("EventBatch", "EventBatch", EventBatch),
    ("FleetEvent", "FleetEvent", p.FleetEvent),
    ("Alert", "Alert", p.Alert),
    ("Register", "Register", p.Register),
    ("RegisterReply", "RegisterReply", p.RegisterReply),
    ("Uplink", "Uplink", p.Uplink),
    ("UplinkReceipt", "UplinkReceipt", p.UplinkReceipt),
    ("Downlink", "Downlink", p.Downlink),
    ("DownlinkAck", "DownlinkAck", p.DownlinkAck),
    ("Report", "Report", Report),
    ("Answer", "Answer", Answer),
    ("Ask", "Ask", Ask),
    ("AskEnded", "AskEnded", AskEnded),
    ("Telemetry", "Telemetry", p.Telemetry),
    ("WorldMessage", "WorldMessage", p.WorldMessage),
    ("WorldReply", "WorldReply", p.WorldReply),
    ("Operations (the `op` of a Request)", "operations", OperatorOp),
    ("MapSnapshot", "MapSnapshot", mf.MapSnapshot),
    ("MapDelta", "MapDelta", mf.MapDelta),
    ("SimStatus", "SimStatus", mf.SimStatus),
    ("StatusUpdate", "StatusUpdate", mf.StatusUpdate),
    *[(f"OpReply.value of `{op}`", f"value-{op}", model) for op, model in v.VALUES.items()],
]


def schemas() -> dict[str, str]:
    """File name -> its JSON Schema text."""
    out = {}
    for _, name, model in SCHEMAS:
        schema = TypeAdapter(model).json_schema()
        out[f"{name}.json"] = json.dumps(schema, indent=1) + "\n"
    return out


def _appendix() -> str:
    rows = [(title, f"[{name}.json]({SCHEMA_DIR}/{name}.json)") for title, name, _ in SCHEMAS]
    return _table(("message", "schema"), rows)


# the limits every receiver applies (backend/core/limits.py): (what, limit, to what)
LIMIT_ROWS: list[tuple[str, str, str]] = [
    ("message", f"{LIMITS.payload:,} bytes ({LIMITS.payload // MiB} MiB)", "one payload, any key"),
    (
        "nesting",
        f"{LIMITS.depth} levels",
        "objects and arrays in one message (`{}` is one level)",
    ),
    (
        "string",
        f"{LIMITS.text:,} characters",
        "every string, object keys included (labels, `info`, parameter values...)",
    ),
    ("array, object", f"{LIMITS.items:,} items, entries", "every array and object"),
    (
        "parameter value",
        f"{LIMITS.value_depth} levels",
        "nesting inside one skill parameter's value (refused with `bad_param`)",
    ),
]


PROSE_1 = f"""# missionctl protocol, version {PROTOCOL_VERSION}

This is what a third party needs to connect a robot, a console or a script
to a missionctl mission server without reading our code. Transport is
[Eclipse Zenoh](https://zenoh.io) 1.x; every payload is UTF-8 JSON of the
models whose JSON Schemas are in [protocol/](protocol/) (listed at the end).
The mission server *is* the Zenoh router (default `tcp/127.0.0.1:7447`);
robots and consoles connect to it. A robot written in Python does not need
this document: it uses the robot agent SDK, see [robots.md](robots.md).

The ground may be minutes away from its robots, or out of their reach for a
while. So nothing between ground and robot waits for an answer: every
command to a robot is an entry of its **uplink**, sent until the robot has
answered it, applied by the robot once; everything a robot says (its status
reports and its answers to commands) is its **downlink**, one numbered
sequence the ground applies strictly in order. What the robot says it did is
what the mission shows.

Version {PROTOCOL_VERSION} replaces version 1's synchronous robot commands. A version 1
robot registering (on `mc/v1/server/register/ROBOT`) is answered `accepted:
false` with a sentence saying so; any other version 1 query gets an
`ErrorReply` with code `protocol_mismatch`.

Conventions: names of robots, markers and barriers match
`^[A-Za-z][A-Za-z0-9_-]*$` (any such name: `robot` too); skill ids match
`^[A-Za-z0-9][A-Za-z0-9_.-]*$`; sessions `^[A-Za-z0-9_-]+$` (at most 64).
Times are ISO 8601 with a zone. A refusal is always a Zenoh `reply_err` whose
payload is an `ErrorReply` (`code` is stable, see Error codes; `message` is a
sentence for a person naming robot, skill and reason). Every message is
checked against its schema (unknown fields are refused); the server answers
a query it cannot read with `reply_err` (`bad_request` from a client,
`bad_message` from a robot, naming the field, and an `Alert` naming the
robot). A publication nobody can read (telemetry, say) is ignored by its
readers; missionctl's consoles raise an "unreadable message" alert naming
the key and the field, once per key (`missionctl ctl watch` prints it too).

## Zenoh settings of a client (robot, console, script)

- `mode`: `"client"`; `connect/endpoints`: the server's endpoints (e.g.
  `["tcp/127.0.0.1:7447"]`); `listen/endpoints`: `[]`.
- `scouting/multicast/enabled`: `false`, `scouting/gossip/enabled`: `false`,
  `scouting/delay`: `0` (else opening waits ~500 ms).
- `connect/timeout_ms`: default (opening fails at once when no router
  answers: retry, or set `-1` to block until it answers). After a router
  restart a client reconnects by itself (within about a second): robots
  register again when the server's token reappears.
- A robot: `transport/link/tx/lease` (ms) bounds how long a hung process
  keeps its presence (missionctl's agent uses 1000; Zenoh's default is 10 s).
  A robot name is owned by one session at a time (see Registration).
- Queries: consolidation `NONE`, a timeout of a few seconds plus the round
  trip (2·D on a link D seconds long; the server waits as the uplink's rule
  says): every query here is answered at once on arrival (nothing waits for
  the other side); no answer means send again later.
- Publications (telemetry): congestion control `BLOCK`.
- Accounts and TLS: [security.md](security.md) (an operator queries only
  `{Keys.op_as("USER")}`; a robot account only its robots' keys).

### Limits
Every receiver holds a message to these limits before it reads it (the
mission server its queries and robots' downlinks, robots their uplink and
world queries, consoles telemetry):

"""

PROSE_LIMITS = f"""
A query over a limit is answered `reply_err` with `code: limit_exceeded` and a
`message` naming the field path and the limit, with at most
{LIMITS.echo} characters of the value (`op.label: 8,000,000 characters, more than
the limit of {LIMITS.text:,} ('xxxx'…)`); nothing of it is applied. An operation
whose change the server cannot journal and read back as it is (its journal
must always replay) is refused with `code: not_replayable`, and nothing
changes.

## Key space

"""

PROSE_2 = """
The server's publications are declared with congestion control `BLOCK`.
Events are small: one `EventBatch` per applied operation, never a full-state
dump (except `mission_replaced` when a whole mission is loaded). The batches
of operations the server handled in a row share one message: a JSON array of
`EventBatch`, in revision order; a lone operation's batch is a plain object.

Each event is typed by its `ev`: a skill's execution moving on is
`skill_status` (`status`, `info`, `attempt`, and `at`, when it happened: the
first `running` sets the skill's `started_at`, `success`/`failure` its
`finished_at`, back to `idle`/`idle_synchronized` clears `started_at`); a
change to its plan is `skill_edited` (`label`, `params`, `bindings`,
`policies`); a command moving on is `command_changed` (`state`, `sent`,
`settled`, `answered`, `cancel_requested`, `reason`, `done`, `kept`). In all
three a field left out (or `null`) is unchanged. Servers before these were
typed published `skill_changed` and `command_changed` with a `changes`
object; their journals still replay (read as the typed events).

## Statuses

`idle` (unsynchronized, editable), `idle_synchronized` (queued on the robot),
`synchwaiting` (waiting at a barrier), `running`, `paused`, `success`,
`failure`. A robot's list always reads: finished log, at most one active
skill, queued skills, unsynchronized skills. Robots may report these
transitions (anything else is refused with `bad_report`):

"""

PROSE_3 = f"""
## The robot link

### Sessions and one owner per name
Each start of a robot's software is a new **session** (a random token, e.g.
12 hex digits). The robot declares its presence token
`{Keys.alive("ROBOT", "SESSION")}`, and every `Register`, `Downlink` and
`UplinkReceipt` carries the session. A robot name has one owner: the session
whose registration was accepted last. A registration of another session
while the owner is online is refused (`RegisterReply.code` `taken`, with a
sentence): that robot must not execute anything (it holds and runs nothing;
missionctl's agent asks again every 5 s, so it takes over once the other one
is gone). The owner is offline from when its presence token disappears
(killed: at once; hung or cut off: after its lease) until it registers
again: a session that lost its lease and comes back is told
`not_registered` on its next `Downlink` and must register again (and is
reconciled). Another session's token never changes the owner's presence.

### Registration and reconciliation
1. The robot connects, declares its uplink and world queryables, then its
   presence token, and watches `{Keys.SERVER_ALIVE}` (liveliness subscriber
   with history: the token may be there already).
2. Whenever the server token appears (start, server restart), and whenever
   the server answers `not_registered`, the robot queries
   `{Keys.register("ROBOT")}` with `Register{{manifest, session, queue,
   downlink, last_seq, uplink_applied, sent}}`: its manifest (`name` is
   ROBOT, `type` the robot type the mission gives it, `protocol`
   {PROTOCOL_VERSION}, modules and skills with SemVer), what it holds, and its
   downlink messages not acknowledged yet.
3. The server applies the `downlink` (in order, see The downlink); then, if
   nothing is missing up to `last_seq`, makes the mission agree with the
   robot's `queue`, both ways: skills the mission holds as synchronized to the
   robot that it lacks go back to the plan (`missing`); skills it holds that
   the mission has as unsynchronized (`idle`) become synchronized again with
   the robot's status (`adopted`; not while a pending sync of them waits for
   its answer, and not when `skill`/`params` show another copy); skills it
   holds that the mission does not give it (unknown, another robot's,
   finished, or a different copy) are asked back with a `reconcile` command
   (`dropped`). Each case raises an `Alert` of kind `reconcile`.
4. The reply carries `last_seq` (the robot drops what it acknowledges, and
   numbers on after it when it is higher than its own: a restarted robot)
   and `heartbeat_s`. The server then sends the robot every pending command.
5. Refused (`accepted: false`): another protocol version (`protocol`), a
   robot the mission does not name (`unknown_robot`), another type
   (`wrong_type`), the name taken (`taken`). A manifest `name` other than the
   ROBOT of the key is refused with `reply_err` (`bad_register`).
6. After a mission is loaded (`op: load`, `new`), each online robot is told
   `not_registered` on its next `Downlink` and registers again: what it
   holds is compared with the new mission as in step 3.

**Skill versions.** `Manifest.skills` maps each skill the robot offers to the
version it implements (SemVer). The ground refuses a sync or a retry
(`incompatible`, nothing is queued) when the robot's manifest lacks the
skill or implements another major version than the skill library's
`version`; minor and patch versions may differ. A robot that never
registered gets the command anyway and refuses (`refused`) what it cannot run.

### The uplink: commands, ground → robot
An operation on a robot (sync, unsync, run, pause, stop, reset, retry) is
applied at once by adding a **command** to the robot's uplink in the
mission (`mission.uplink[ROBOT]`, every change an event): `id` (the number
operators see, "command 17"), `seq` (its place in the robot's sequence),
`op`, `command` (what the robot gets: `enqueue`, `dequeue`, `run`, `pause`,
`stop`, `reset`), `skills`, `created`, `sent`, `expires`, `settled`, and its
`state` (the list keeps the robot's pending commands and its last
{KEEP_SETTLED} settled ones: an older settled one is dropped when another
settles, without an event of its own; see Applying events to a mirror):

- `queued`: certainly not on the robot (never transmitted, or every
  transmission was refused);
- `sent`: transmitted, so it may be on the robot;
- `acked` (the robot applied it), `refused` (the robot refused it, `reason`),
  `expired`, `cancelled`: settled.

The server queries `{Keys.uplink("ROBOT")}` with an `Uplink` holding **every
pending command** of that robot in seq order, whenever there is one and the
robot is registered (see When a command leaves).

The robot answers the query **at once** with `UplinkReceipt{{session,
applied}}` (or `reply_err` `unreachable` when out of range, `wrong_session`
when the Uplink names another session) and processes the commands when they
have arrived: in `seq` order, each exactly once. A command with a seq at or
below the last one it processed is skipped (the server sends every pending
command each time); a seq may be missing (a command withdrawn before it was
ever sent: do not wait for it). For each processed command it makes an
`Answer`, the next message of its downlink:

- `cancel` set: `outcome: cancelled`, nothing applied;
- past `expires` (its clock): `outcome: expired`, nothing applied;
- else apply it and answer what it actually did: `applied` with `queued`
  (enqueue: the ids it holds now, which may be fewer than sent), `removed`
  and `kept` (dequeue: removed unless started; reset: everything), or
  `refused` with a `reason` (e.g. no handler for a skill). Reports the
  command causes (a stop's `idle_synchronized`) come before its answer.

The ground applies the answer, never the request: enqueued ids become
`idle_synchronized` (moved to the end of the queue, in the robot's order),
the others go back to `idle` with an `Alert` (kind `command`) naming robot,
command and reason; removed ids go back to `idle` at the head of the plan,
in order; a retry's new attempt joins the mission right after the log and
the active skill. While a command is pending, its skills are locked (a
sync's: "uplinking", not editable, nothing placed before them; an unsync's:
not asked back twice; a retry's failed skill: not retried twice).

**Commands run on, in order.** Several commands may be pending for one
robot: a run after a sync applies after the enqueue; a second sync sends the
idle skills after those still uplinking.

**Expiry.** `expires` (from `--expire` or the server's default) is when the
robot must stop applying it. A queued command whose expiry passes is settled
`expired` by the server (it never left; an `Alert` says so, its skills are
editable again). A sent one is settled by the robot's answer.

**Cancel** (`op: cancel {{command}}`): a queued command not being transmitted
is `cancelled` at once (final: the robot never gets it). Otherwise (sent, or
its transmission under way) it may be on the robot already: the command gets
`cancel_requested` and goes out again with `cancel` set; the robot's answer
says which way it went ("cancel requested" until then). If the transmission
turns out not to have arrived, the server settles it `cancelled`. The undo
of a sync cancels its command while it is queued, and is refused
(`cannot_undo`) once it was sent or answered.

**When a command leaves, and how long the server waits.** Transmissions are
pipelined: a command leaves at once, in a transmission of its own, whatever
earlier transmissions still wait for their receipt (a robot D seconds away
receipts one 2·D later). Each carries every pending command, so the robot
meets them in seq order whichever transmission it reads first. The server
transmits:

- at once when a command is added, or its cancel asked;
- at once when the robot registers: every pending command again;
- after a transmission that did not reach the robot (`unreachable`, no
  responder, another session's receipt): again after {tm.RETRY_S:g} s,
  doubling up to {tm.RETRY_MAX_S:g} s, or at once when a `Downlink` of the
  robot arrives;
- after a transmission without a receipt in time: again after
  {tm.RETRY_S:g} s, doubling up to {tm.RETRY_MAX_S:g} s;
- every {tm.RESEND_SENT_S:g} s (or {tm.RESEND_DELAYS}·D, when longer) while
  a sent command has no answer.

It waits **{tm.RECEIPT_S:g} s + {tm.DELAY_MARGIN}·D** for a transmission's
receipt (the query and its receipt each cross the link once, plus one D of
margin), D being the robot's one-way delay as the ground estimates it
(`RobotInfo.delay_s`; 0 until it is known). Queued commands become `sent`
when a receipt of the registered session comes, or when none came in time
(they may have arrived); their `sent` is when that transmission left.

**A robot that applied a command the ground had given up on** (cancelled or
expired, e.g. the robot got it in the instant the server stopped): its
answer is the truth. Skills it queued that are still idle and unchanged
become synchronized; others (edited, deleted) are asked back with a
`reconcile` command; an `Alert` names robot, command and skills.

### The downlink: reports and answers, robot → ground
A robot's **reports** (`Report{{robot, seq, id, status, info, attempt, at}}`,
one per status change) and its **answers** (`Answer{{robot, seq, command,
outcome, reason, queued, removed, kept, at}}`) share **one sequence**: `seq`
is 1, 2, 3, ... per robot (continued after `RegisterReply.last_seq` when
that is higher). They stay in the robot's outbox until acknowledged, and go
to `{Keys.downlink("ROBOT")}` as `Downlink{{robot, session, messages,
uplink_applied, sent}}`, the oldest first. With nothing to say the robot
sends an empty `Downlink` every `heartbeat_s` (5 s): the ground's "heard N s
ago" and one-way delay estimate come from these (`sent`: when it left the
robot, its clock).

The server applies the messages strictly in `seq` order, each once: one at
or below the last applied is skipped (sent again); one past a gap is **not**
applied: `DownlinkAck.missing` names the gap and the robot sends again from
`last_seq` + 1 (an `Alert` of kind `robot_error` names it once). A message
the rules refuse is consumed all the same: journaled as refused, alerted
(kind `report_refused`), listed in `DownlinkAck.refused` (in a registration:
`RegisterReply.refused`) as an `ErrorReply` whose `seq` is the message's and
whose code is `bad_report`, whatever is wrong with it: a status change the
table forbids, a report on a skill the mission does not have or that is not
this robot's, an answer to a seq the uplink does not hold (never sent, or
settled long ago) or answered already. The acknowledgement is cumulative (`last_seq`); the
`Uplink` carries it too (`downlink_ack`). When the server cannot write its
journal it answers `reply_err` (`journal_failed`) and applies nothing of what
it could not journal: the robot keeps its outbox and sends it again.

A `Downlink` from a session that is not the registered, online one is
refused with `not_registered` (register again); one whose `robot` is another
robot with `bad_message`. A message in it (or in a `Register.downlink`)
naming another robot is consumed as refused, with `bad_message`: its number
is used up, that robot is not touched.

**Questions** (docs/robots.md "Asking the operator"): a skill's handler may
ask the operators, `Ask{{robot, seq, ref, skill, text, choices, default,
timeout_s, at, due}}` in the same sequence (`ref`: the robot's own name for
it, unique per run; at most {MAX_CHOICES} choices of {MAX_CHOICE} characters, a
text of {MAX_QUESTION_TEXT}). The ground opens it (`question_asked`, a
`question` alert). An operator's `answer_question` queues an `answer` command
on the robot's uplink (`{{cmd: "answer", question, ref, choice, by}}`,
expiring at the question's `due`); the robot answers it `applied` (it goes on
with the choice: the question is `answered`) or `refused` (it no longer asks).
When `timeout_s` of mission time passes first the robot goes on with the
default and says so: `AskEnded{{robot, seq, ref, outcome: "default", choice,
at}}`; a skill stopped or ended while asking sends `outcome: "withdrawn"`.
`Register.asking` lists the refs it still asks: the mission's other open
questions of that robot are withdrawn (a restart ended them).

**Answer a command before anything that waits for the server**: process it,
put its answer in the outbox and reply to the Uplink query; never query the
server from inside a query callback.

### Rules for every field

"""

KINDS_TEXT = ", ".join(f"`{k}`" for k in get_args(ParamType))

PROSE_PARAMS = f"""
### Parameters, typed
A skill's parameters travel as JSON values (`SkillInstance.params`) with
their kinds: `Enqueue.kinds[SKILL][PARAMETER]` is the kind the library gives
each parameter of every skill the command carries ({KINDS_TEXT}).
Read each value by its kind, never by its shape (a `dict` parameter may look
like a position): a `pose` is `{{x, y, z, roll, pitch, yaw}}` (metres,
radians), a `position` `{{x, y, z}}`, an `area` a list of at least 3
positions; `enum`, `marker` and `robot` values are names; the others are
the JSON values themselves. A parameter bound to a marker arrives as the
marker's value in its parameter's kind. The server has checked every value
and filled in every default of the library before the command leaves: a
parameter listed in `kinds` but missing from `params` is an optional one
left unset (null to a handler).

Each accepted registration gives the robot the library's signature of each
skill its manifest offers (`RegisterReply.skills[SKILL]`: each parameter's
kind, the required ones, and the `defaults` the server fills in for one
left out): compare the handlers with it once, and call a skill the robot
runs on its own (a recharge before a skill, `policies.recharge_below`) with
its `defaults`.
"""

PROSE_4 = """
### Run, pause, stop, reset, and the robot's mode
The robot starts halted. `run` enters run mode: it executes its queue head to
tail and stays in run mode when the queue drains (skills enqueued later start
at once). Run on a paused skill resumes it; after a failure, run goes on
with the next skill. `pause` pauses the running skill (`paused`), leaving run
mode; refused at a barrier (the table has no `synchwaiting` → `paused`).
`stop` returns the active skill to the head of the queue (`idle_synchronized`;
the next run starts it from the beginning), leaving run mode. `reset` = stop
and remove everything queued (its answer lists the removed ids, which return
to the plan). A failure leaves run mode: the operator decides (retry, run to
go on, unsync). The mode as telemetry shows it:

"""

PROSE_5_CASES = """
**Awkward commands.** What missionctl's agent does (and what the ground
expects) when a command meets a state it does not fit:

"""

PROSE_5 = f"""
On the ground, run/pause/stop/reset are refused when they cannot apply to
what the ground knows plus its pending commands (run with nothing queued nor
being synchronized; pause or stop with nothing active, unless a run is
pending: the robot may be executing by now). With `robot` omitted they go to
every robot they apply to.

### Failure and retry
A failing skill becomes `failure` and the robot halts its queue. `op: retry
{{id}}` queues an `enqueue` with `front: true` of the new attempt `ID.N`
(attempt N, same parameters); once the robot has it, it joins the mission
right after the failed one (which stays in the log). A skill with
`policies.retries: N` is retried by the robot itself: it reports `running`
again with `attempt` + 1 (never `failure` before its last attempt).

### Barriers (robot to robot; the server is not in this loop)
Each skill of a barrier reaches its robot with `Enqueue.barriers[skill id] =
{{barrier, partners: {{robot: skill id}}}}`. A robot reaching it reports
`synchwaiting`, subscribes (with history) to
`{Keys.barrier_ready("BARRIER", "*")}`, **then** declares its own token
`{Keys.barrier_ready("BARRIER", "ROBOT")}` (in this order no robot can miss
the last arrival), and watches its partners' presence
(`{Keys.alive("PARTNER", "*")}`). When every partner's ready token is present,
it reports `running`. While a partner is offline it reports `synchwaiting`
again with info "waiting for PARTNER (offline)".

**Token lifetime**: declared when the robot reaches the barrier skill, held
while the skill is waiting and running, withdrawn when the skill ends
(success, failure), is stopped or reset, or the robot's session ends (the
router drops it at once for a killed process, after its lease for a hung
one). A partner that arrives while the others still run their barrier skill
still sees their tokens and starts; one that arrives after they finished
waits (the barrier is met by the robots at it together).

### World knowledge (robot to robot)
`WorldMessage{{kind: ask|tell, sender, topic, data}}` to
`{Keys.world("ROBOT")}`; the answer is a `WorldReply{{known, data}}`. Only
robots (and tools) query it; a robot that shares no knowledge may answer
every ask with `known: false`.

Precedence (`policies.after`, `Enqueue.after`) uses two topics. A robot
whose skill another robot waits for answers the ask `missionctl.outcome`
(`data: {{skill}}`) with `{{status}}`: `success`, `failure`, the skill's
status while it holds it, or `unknown`; it notes the asker while the skill
has not ended and, when it ends, tells it (`missionctl.outcome_ended`,
`data: {{skill, status}}`). It answers for skills it finished before a
restart from `RegisterReply.outcomes`. The waiter asks again when the other
robot's presence changes or it comes back within reach, else rarely.

## Consoles and scripts

### Late join and event stream
1. Subscribe to `{Keys.EVENTS}` (and `{Keys.FLEET}`, `{Keys.ALERTS}`,
   telemetry) first.
2. Query `{Keys.STATE}` (`StateRequest`) for a `StateSnapshot`: the mission
   (with every robot's uplink), the library, the robots (presence, manifest,
   `session`, `heard`, `delay_s`). Apply it, then the buffered batches whose
   `revision` is greater than the snapshot's.
3. Apply each batch with `revision == current + 1`, the batches of an array
   in order. A larger revision means a gap: query the state again.
4. When the server's token disappears, show "reconnecting"; when it (or the
   Zenoh link) comes back, query the state again. A new `server_id` means
   the server restarted (it resumed from its journal).

### An operation
`Request{{client, request_id, expected_revision?, op}}` to `{Keys.OP}`. The
same `(client, request_id)` is applied once: retry freely. With
`expected_revision`, the operation is refused (`stale`) if anything it
touches changed after that revision. The reply is `OpReply{{revision,
value, notes}}` (the value per operation: see the appendix) or an
`ErrorReply`; it leaves before the operation's `EventBatch`. An operation on
a robot returns once its command is queued (`value.command`); its progress
arrives as `command_changed` events (`sent`, then the robot's answer), and
the skills change with the answer. On a server with accounts
(docs/security.md) an operator may query only `{Keys.op_as("USER")}`.

### Applying events to a mirror
A mirror applies the events of each batch in order, then sets the mission's
`revision` to the batch's ("the revision" below). Events carry only what
changed; they maintain every field of the snapshot's mission, so a mirror
that applied every batch equals a fresh snapshot (`mission.uplink`
included):

"""

PROSE_LOAD = f"""
### Loading a mission
`op: load {{mission, keep_state}}` replaces the mission (one
`mission_replaced` event). It is refused while commands are pending
(`robot_busy`) or robots hold synchronized skills (`robots_busy`: reset
them). The mission comes in **as a plan**: every skill that is not finished
is `idle` (its status was some robot's once; what the robots hold now is
theirs to say), finished ones stay as the log, and a barrier left with a
finished skill and an idle one is dissolved; `value.reset` and
`value.dissolved` say which. With `keep_state: true` the file's statuses are
kept, refused (`robots_online`) while a robot of the mission is online: the
robots reconcile them when they register. Then every online robot registers
again and is reconciled (see Registration, step 6). The robots' sequence
numbers and uplinks go on across missions. `op: new {{name}}` loads an empty
mission with the same robots.

### Plan checks and waivers
The plan checks ({_check_names()}) run on the ground; a sync is refused
(`plan_errors`) while an error finding names a skill it would send. A
finding's id is `RULE:SUBJECT` (pattern `{CHECK_ID_PATTERN}`, e.g.
`barrier.deadlock:b1+b2`). `op: waive {{check, reason}}` lets that finding's
skills be synchronized (journaled; a `waiver_set` event; again with another
reason, the reason is replaced); `op: unwaive {{check}}` withdraws it
(`waiver_removed`). A check id whose rule is not one of the above is refused
`unknown_check`; an unwaive without a waiver `unknown_waiver`.

### The link, as consoles show it
Per robot: `RobotInfo.delay_s` (the one-way delay, least of the last 8
`now − sent` of its messages; clocks must agree), `RobotInfo.heard` (when
the server last heard from it; a `FleetEvent` carries it at least every
10 s while the robot talks; a console also counts its telemetry), and the
pending commands with their age (`now − created`, `now − sent`) and
`expires`. A robot offline, out of range or silent for more than three
heartbeats (15 s) is stale: show its last known state as such.

### Contact state
`RobotInfo.contact` is computed by the server: `in_contact` (with `closes`,
when its window closes), `out_of_contact` (present, its window closed; with
`next_contact`, when the next one opens; null: none ahead) or `offline` (no
presence: offline wins over any window). Times are mission time on
`clock`: `sim` (seconds since the simulator started) or `wall` (POSIX
seconds, UTC). The windows (`source`) come from the server's
`--contact-windows FILE` (`format: missionctl/contact-windows@1`, wall
clock, see docs/deployment.md) for the robots it lists, else from the
simulator's `--comms-window` (the `comms_window` of its status, which the
server follows on `{mf.KEY_STATUS_LIVE}`), else none: always in contact. A
`FleetEvent` carries the robot when its state changes (within a second of
a window opening or closing). A robot out of contact is never shown
"online", and its last known state is drawn as such.

## Error codes

"""

PROSE_CODES = """
Which operation may be refused with which code, beyond those of every
request (`bad_request`, `read_only`, `stale`, `journal_failed`,
`limit_exceeded`, `not_replayable`):

"""

PROSE_6 = """
`RegisterReply.code` when not accepted:

"""

PROSE_7 = f"""
## A worked trace: add → sync → run → report, one-way delay {D:g} s

A console adds a skill to `lru1` and synchronizes it, then runs the robot;
the robot is {D:g} s away. Times are the ground's; the robot's messages say
when they left it (`sent`), {D:g} s earlier. The console's operations return
at once; the robot gets the enqueue at t = 3 s, answers, and its answer is
on the ground at t = 5 s (2·D after the command left). Default fields are
left out below.

"""

PROSE_8 = f"""
## Map feed (simulator → consoles)
The site as grids cut into `tile` × `tile` cells (`MapMeta`); a tile is
`base64(zlib(uint8 cells, row-major))`, rows south to north from `y0`,
columns west to east from `x0`. Layers: `terrain` (0 unknown, 1 free,
2 slow, 3 impassable) and `coverage` (0 no link, 1..255 link quality).
Objects (lander, payload boxes, discovered regions, identified stones) ride
along whole when any changed. Robot poses come with the robots' telemetry.
1. Subscribe to `{mf.KEY_MAP_DELTA}`, then query `{mf.KEY_MAP_SNAPSHOT}`
   (no reply: no simulator is running; query again when a delta arrives).
2. Apply buffered deltas whose `seq` is greater than the snapshot's, then
   each delta with `seq == current + 1` and the same `feed`.
3. A larger `seq` (a gap) or another `feed` (the simulator restarted): query
   the snapshot again. (`backend.client.mapfollow.MapFeed` does all of this.)

## Long links and thin links

A deployment through a site relay ([deployment.md](deployment.md)) puts a
one-way delay D and a narrow link between the ground and the robots.

**Timeouts.** Every process is given the same hint D
(`--link-delay-hint`); with RTT = 2 D, its Zenoh config gets
`transport/unicast/open_timeout` and `accept_timeout` and
`routing/interests/timeout` = 10 s + 4 RTT (the handshake's ~3 round trips),
`transport/link/tx/lease` = 10 s + 2 RTT (a robot's own lease at least that)
with `keep_alive` 4 per lease, and every protocol query waits its LAN
timeout + 2 RTT. D = 0 keeps Zenoh's defaults and missionctl's (a robot's
lease 1 s). One formula, in `backend/transport/timeouts.py`.

**Telemetry** goes on change: a sample when a field moved beyond its
deadband (position 0.5 m; yaw, roll, pitch 5°; battery 0.01; link 0.05;
progress 0.05; an `eta_s` off by 2 s or 10 % from the last one counted down)
or any other field changed, at most the robot's rate cap a second, and at
least every 5 s. It is compact JSON of `Telemetry`: fields equal to their
default are left out (a reader's model puts them back), numbers rounded to
three decimals (`eta_s` one). A reader counts a running skill's `eta_s`
down between samples.

**The simulator's live status** (`{mf.KEY_STATUS_LIVE}`) is a
`StatusUpdate`: `full` (the first publication, then once a minute) or
`patch`, a JSON merge patch (RFC 7386) of `SimStatus` against the previous
publication (`seq` consecutive within one `feed`). A follower subscribes,
queries `{mf.KEY_STATUS}` (whose `SimStatus` names the `feed` and the last
`seq` it includes), applies the patches that follow, and queries again after
a gap or another `feed` (`backend.client.simstatus.SimStatusFeed`). A plain
`SimStatus` on the live key is a full one.

## Appendix: message schemas

JSON Schema (generated from the models) of every message and every
`OpReply.value`, one file each in [protocol/](protocol/):

"""


PROSE_ALERTS = f"""
## Alerts

The server alone raises alerts about robots and the mission (an `Alert` on
`{Keys.ALERTS}`); `robot`, `skill` and `command` say whom it is about,
`message` is a sentence, `kind` what happened (the table below). Alerts are
numbered (`id`) per server run; the last {ALERTS_KEPT} are in every
`StateSnapshot.alerts`, so a console that was away takes what it missed,
each once (by `server_id` and `id`). A robot's battery falling below
{LOW_BATTERY:.0%} (`low_battery`) and its telemetry saying it left
communication range (`out_of_range`) are alerted once per crossing.

"""


def render() -> str:
    return "".join(
        [
            PROSE_1,
            _table(("what", "limit", "applies to"), LIMIT_ROWS),
            PROSE_LIMITS,
            _table(("key", "kind", "who declares", "payload"), KEY_SPACE),
            PROSE_2,
            _table(("from", "to"), REPORTED_TRANSITIONS),
            PROSE_ALERTS,
            _table(("kind", "meaning"), [(f"`{k}`", MEANING[k]) for k in AlertKind]),
            PROSE_3,
            _table(("field", "rule"), FIELD_RULES),
            PROSE_PARAMS,
            PROSE_4,
            _table(("mode", "meaning", "next"), MODES),
            PROSE_5_CASES,
            _table(("case", "the robot"), ROBOT_CASES),
            PROSE_5,
            _table(("event", "fields", "apply"), EVENT_RULES),
            PROSE_LOAD,
            _table(("code", "from", "meaning"), ERROR_CODES),
            PROSE_CODES,
            _table(("operation", "codes"), OP_CODES),
            PROSE_6,
            _table(("code", "meaning"), REGISTER_CODES),
            PROSE_7,
            _trace_text(),
            PROSE_8,
            _appendix(),
        ]
    )


def write(docs: Path) -> list[Path]:
    """Write protocol.md and protocol/*.json under `docs`; the files that changed."""
    wanted = {docs / "protocol.md": render()}
    wanted |= {docs / SCHEMA_DIR / name: text for name, text in schemas().items()}
    changed = []
    for path, text in wanted.items():
        if not path.exists() or path.read_text(encoding="utf-8") != text:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
            changed.append(path)
    return changed


def stale(docs: Path) -> list[str]:
    """What differs from what would be written (missing, changed, extra schema files)."""
    out = []
    if (docs / "protocol.md").read_text(encoding="utf-8") != render():
        out.append("protocol.md")
    want = schemas()
    have = {f.name for f in (docs / SCHEMA_DIR).glob("*.json")}
    for name, text in want.items():
        f = docs / SCHEMA_DIR / name
        if not f.exists() or f.read_text(encoding="utf-8") != text:
            out.append(f"{SCHEMA_DIR}/{name}")
    out += [f"{SCHEMA_DIR}/{n} (not generated)" for n in sorted(have - set(want))]
    return out


if __name__ == "__main__":
    docs = ROOT / "docs"
    if "--check" in sys.argv[1:]:
        diff = stale(docs)
        print("\n".join(diff) or "up to date")
        sys.exit(1 if diff else 0)
    for path in write(docs):
        print(f"wrote {path.relative_to(ROOT)}")
