"""Writes docs/protocol.md: the prose below plus JSON Schemas generated from
the protocol models (so the document cannot drift from the code; a test
checks it is up to date).

    python -m backend.protocol.doc > docs/protocol.md
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from typing import Any

from pydantic import TypeAdapter

from backend.core.events import EventBatch
from backend.core.limits import LIMITS, MiB
from backend.core.ops import OperatorOp, Report
from backend.protocol import mapfeed as mf
from backend.protocol import messages as p
from backend.protocol.keys import PROTOCOL_VERSION, Keys

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
        f"`{Keys.EVENTS}`",
        "publication",
        "server",
        "`EventBatch`, or a JSON array of them (revisions consecutive)",
    ),
    (f"`{Keys.FLEET}`", "publication", "server", "`FleetEvent` (presence, manifest)"),
    (f"`{Keys.ALERTS}`", "publication", "server", "`Alert`"),
    (
        f"`{Keys.PING}`",
        "queryable",
        "server",
        "anything → `pong` (raw-transport baseline of the benchmarks)",
    ),
    (f"`{Keys.register('ROBOT')}`", "queryable", "server", "`Register` → `RegisterReply`"),
    (f"`{Keys.reports('ROBOT')}`", "queryable", "server", "`ReportBatch` → `ReportAck`"),
    (f"`{Keys.alive('ROBOT')}`", "liveliness token", "robot", "—"),
    (
        f"`{Keys.command('ROBOT')}`",
        "queryable",
        "robot",
        "`Command` → `CommandReply` / `ErrorReply`",
    ),
    (f"`{Keys.telemetry('ROBOT')}`", "publication", "robot", "`Telemetry`"),
    (f"`{Keys.world('ROBOT')}`", "queryable", "robot", "`WorldMessage` → `WorldReply`"),
    (
        f"`{Keys.barrier_ready('BARRIER', 'ROBOT')}`",
        "liveliness token",
        "robot",
        "— (present while waiting at a barrier)",
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
        "`SimStatus` (on change, at least every 2 s)",
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


def _table(head: tuple[str, ...], rows: Sequence[tuple[str, ...]]) -> str:
    """A markdown table."""
    lines: list[tuple[str, ...]] = [head, tuple("---" for _ in head), *rows]
    return "".join("| " + " | ".join(cells) + " |\n" for cells in lines)


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


PROSE = (
    f"""# missionctl protocol, version {PROTOCOL_VERSION}

This is what a third party needs to connect a robot, a console or a script
to a missionctl mission server without reading our code. Transport is
[Eclipse Zenoh](https://zenoh.io) 1.x; every payload is UTF-8 JSON of the
models below. The mission server *is* the Zenoh router (default
`tcp/127.0.0.1:7447`, multicast scouting off); robots and consoles connect to
it in `client` mode. A robot written in Python does not need this document:
it uses the robot agent SDK, see [robots.md](robots.md).

Conventions: names of robots, markers and barriers match
`^[A-Za-z][A-Za-z0-9_-]*$`; skill ids match `^[A-Za-z0-9][A-Za-z0-9_.-]*$`.
Times are ISO 8601 with a zone. A refusal is always a Zenoh `reply_err` whose
payload is an `ErrorReply` (`code` is stable, `message` is a sentence for a
person naming robot, skill and reason).

Every message is checked against its schema below (unknown fields are
refused). The server answers a query it cannot read with `reply_err`
(`code: bad_request`, naming the field); a publication nobody can answer
(telemetry, say) is ignored by its readers, and missionctl's consoles raise
an "unreadable message" alert naming the key and the field, once per key
(`missionctl ctl watch` prints it too): the first place to look when a new
robot's telemetry never shows.

### Limits
Every receiver holds a message to these limits before it reads it (the
mission server its queries, robots their world queries, consoles telemetry):

"""
    + _table(("what", "limit", "applies to"), LIMIT_ROWS)
    + f"""
A query over a limit is answered `reply_err` with `code: limit_exceeded` and a
`message` naming the field path and the limit, with at most
{LIMITS.echo} characters of the value (`op.label: 8,000,000 characters, more than
the limit of {LIMITS.text:,} ('xxxx'…)`); nothing of it is applied. An operation
whose change the server cannot journal and read back as it is (its journal
must always replay) is refused with `code: not_replayable`, and nothing
changes.

## Key space

"""
    + _table(("key", "kind", "who declares", "payload"), KEY_SPACE)
    + """
Publications are declared with congestion control `BLOCK` (state must not be
dropped). Events are small: one `EventBatch` per applied operation, never a
full-state dump (except `mission_replaced` when a whole mission is loaded).
The batches of operations the server handled in a row (under load) share one
message: a JSON array of `EventBatch`, in revision order; a lone operation's
batch is a plain `EventBatch` object.

## Statuses

`idle` (unsynchronized, editable), `idle_synchronized` (queued on the robot),
`synchwaiting` (waiting at a barrier), `running`, `paused`, `success`,
`failure`. A robot's list always reads: finished log, at most one active
skill, queued skills, unsynchronized skills. Robots may report these
transitions (anything else is refused with `bad_report`):

"""
    + _table(("from", "to"), REPORTED_TRANSITIONS)
    + f"""
## Sequences

### Late join and event stream (consoles, scripts)
1. Subscribe to `{Keys.EVENTS}` (and `{Keys.FLEET}`, `{Keys.ALERTS}`, telemetry) first.
2. Query `{Keys.STATE}`; apply the snapshot; then apply buffered batches
   whose `revision` is greater than the snapshot's.
3. Apply each batch with `revision == current + 1`, the batches of an array
   in order. A larger revision means a gap: query the state again. (A reader
   that cannot read arrays stays correct: it ignores the array, sees the next
   batch as a gap and queries the state again.)
4. When the server's liveliness token disappears, show "reconnecting"; when it
   (or the Zenoh link) comes back, query the state again. A new `server_id`
   means the server restarted (it resumed from its journal).

### An operation
`Request{{client, request_id, expected_revision?, op}}` to `{Keys.OP}`. The
same `(client, request_id)` is applied once: retry freely after a timeout.
With `expected_revision`, the operation is refused (`stale`) if anything it
touches changed after that revision. The reply is `OpReply{{revision, value,
notes}}` or an `ErrorReply`. The reply leaves before the operation's
`EventBatch` (its `revision` is the reply's): a client that needs its own
change in its copy of the mission waits for that batch.

On a server with accounts (docs/security.md) the router's access-control
rules allow an operator to query only `{Keys.op_as("USER")}` with its own
user name, and nobody `{Keys.OP}`; the server records `USER` (taken from
the key, not from `Request.user`) as who made the change. A client learns its
role from `{Keys.account("USER")}` (an observer has no operation key: its
queries get no reply at all, so clients refuse operations locally).

### Robot registration and reconciliation
1. The robot connects, declares `{Keys.alive("ROBOT")}`, its command and
   world queryables, and watches `{Keys.SERVER_ALIVE}` (a liveliness
   subscriber with history: the token may be there already).
2. Whenever the server token appears (start, server restart), the robot
   queries `{Keys.register("ROBOT")}` with `Register{{manifest, queue,
   reports}}`: its manifest (`name` is ROBOT, `type` the robot type the
   mission gives it, `protocol` {PROTOCOL_VERSION}, modules and skills
   with SemVer), its own synchronized queue, and its unacknowledged reports.
3. The server applies the reports, then returns to the plan (`idle`) any skill
   it holds as synchronized to that robot that the robot does not have (it
   restarted; `RegisterReply.missing` and an `Alert` of kind `reconcile` name
   them). The reply carries `last_seq`: the robot continues numbering after
   it.
4. The robot is online (a `FleetEvent`) from an accepted registration until
   its liveliness token disappears: the token alone does not make it online.
   The server answers `RegisterReply{{accepted: false, reason}}` to another
   protocol version, a robot the mission does not name, or a type other than
   the mission's; register again when the server token reappears. A manifest
   `name` other than the ROBOT of the key is refused (`bad_register`).

### Synchronize
1. Operator: `op: sync {{robot, through?}}`.
2. Server: checks the robot is online, offers every skill (by name) with the
   library's major version, locks the skills, and queries
   `{Keys.command("ROBOT")}` with `Enqueue{{skills, barriers}}` (`barriers` maps a
   skill id to its barrier and partner robots' skill ids).
3. Robot: appends them to its queue, answers `CommandReply{{ids}}`.
4. Server: marks them `idle_synchronized` (one `EventBatch`) and replies. No
   answer (out of range, timeout, offline) → the mission is unchanged, and the
   refusal names the robot and why.
5. A reply lost on its way back leaves the robot holding skills the mission
   still shows unsynchronized; the operator synchronizes again. So a robot
   answers an `Enqueue` of skills it holds already as if it had just queued
   them (their ids in `ids`, not queued twice), and leaves out of `ids` those
   it has already run.

### Unsynchronize, and the race with a starting robot
1. Operator: `op: unsync {{robot, from_id?}}`: the queued skills from `from_id`
   to the end.
2. Server → robot: `Dequeue{{ids}}`.
3. Robot: removes those it has not started; answers `CommandReply{{ids:
   removed, kept: started meanwhile, reports}}`. `reports` holds the status
   changes it made and the server has not acknowledged yet (e.g. the skill it
   just started): the server applies them **before** the removal, so the
   started skill is `running` and the others return, in order, to the head of
   the unsynchronized section. The reply to the operator names the kept ones.

### Run, pause, stop, reset
Server → robot: `Run`, `Pause`, `Stop`, `Reset`. The robot changes its
execution and reports the status changes (`Report`, numbered per robot). Run
on a paused robot resumes; after a failure, run continues with the next
queued skill. Stop returns the active skill to `idle_synchronized` (the next
run starts it from the beginning). Reset = stop + remove everything queued;
its reply lists the removed ids, which return to the plan. A robot refuses a
command with `CommandReply{{ok: false, reason}}` (the operator's refusal is
`robot_refused` with that reason) or with a `reply_err` whose `ErrorReply`
`code` reaches the operator.

### Reports
Each status change is a `Report{{robot, seq, id, status, info, attempt, at}}`
with `seq` increasing by one per robot. The robot keeps them in an outbox and
queries `{Keys.reports("ROBOT")}` with `ReportBatch`; `ReportAck.last_seq` tells
which it may drop. While out of reach the outbox grows and is flushed on
return; a report the server already applied is ignored (idempotent). A
refused report is acknowledged too (listed in `refused`) and raises an alert.
When the server cannot write its journal (disk full, file locked or deleted)
it answers the whole batch with a `reply_err` (`journal_failed`) and applies
none of what it could not journal: the robot keeps its outbox and sends it
again (operations get the same refusal; an `Alert` of kind `journal` tells
consoles once, and again when the journal works).
`at` is when the change happened: the first `running` sets the skill's
`started_at`, `success` or `failure` its `finished_at`.

**Answer a command before waiting for anything from the server.** The server
takes a robot's `ReportBatch` and `Register` only once its command in flight
to that robot is answered: a robot that reports from its command handler and
waits for the `ReportAck` before replying blocks both until the command times
out (the operator is told `robot_timeout` although the robot acted). Status
changes made while handling a command go in `CommandReply.reports`, or are
sent after the reply.

### Failure and retry
A failing skill becomes `failure` and the robot halts its queue. The
operator decides: `op: retry {{id}}` creates `ID.N` (attempt N, same
parameters) which the server sends with `Enqueue{{front: true}}`; once
acknowledged it is queued right after the failed one, which stays in the log.
`op: run` continues with the next skill; `op: unsync` takes the rest back.
A skill with `policies.retries: N` is retried by the robot itself: it reports
`running` again with `attempt` + 1 (never `failure` before the last attempt).

### Barriers (robot to robot; the server is not in this loop)
Each skill of a barrier reaches its robot with the partners' robot and skill
ids. A robot reaching it reports `synchwaiting`, subscribes (with history) to
the liveliness tokens `{Keys.barrier_ready("BARRIER", "*")}`, **then**
declares its own token (in this order no robot can miss the last arrival),
and watches its partners' `{Keys.alive("ROBOT")}` tokens. When every partner's
ready token is present, it reports `running`. While a partner is offline it
reports `synchwaiting` again with info "waiting for ROBOT (offline)".

### Map feed (simulator → consoles)
The site as grids cut into `tile` × `tile` cells (`MapMeta`); a tile is
`base64(zlib(uint8 cells, row-major))`, rows south to north from `y0`,
columns west to east from `x0`. Layers: `terrain` (0 unknown, 1 free,
2 slow, 3 impassable) and `coverage` (0 no link, 1..255 link quality).
Objects (lander, payload boxes, discovered regions, identified stones) ride
along whole when any changed. Robot poses are not in the feed: they come
with the robots' telemetry.
1. Subscribe to `{mf.KEY_MAP_DELTA}`, then query `{mf.KEY_MAP_SNAPSHOT}`
   (no reply: no simulator is running; query again when a delta arrives).
2. Apply buffered deltas whose `seq` is greater than the snapshot's, then
   each delta with `seq == current + 1` and the same `feed`.
3. A larger `seq` (a gap) or another `feed` (the simulator restarted): query
   the snapshot again. (`backend.client.mapfollow.MapFeed` does all of this.)

### World knowledge (robot to robot)
`WorldMessage{{kind: ask|tell, sender, topic, data}}` to
`{Keys.world("ROBOT")}`; the answer is a `WorldReply{{known, data}}`.
Only robots (and tools such as `ctl`) query it; the server never does, so a
robot that shares no knowledge may answer every ask with `known: false`.

## Messages (JSON Schema, generated)
"""
)

MODELS: list[tuple[str, Any]] = [  # (title, model or union of models)
    ("Request", p.Request),
    ("OpReply", p.OpReply),
    ("ErrorReply", p.ErrorReply),
    ("StateRequest", p.StateRequest),
    ("AccountInfo", p.AccountInfo),
    ("StateSnapshot (mission and library: see `missionctl schema`)", None),
    ("EventBatch", EventBatch),
    ("FleetEvent", p.FleetEvent),
    ("Alert", p.Alert),
    ("Register", p.Register),
    ("RegisterReply", p.RegisterReply),
    ("Report", Report),
    ("ReportBatch", p.ReportBatch),
    ("ReportAck", p.ReportAck),
    ("Command", p.Command),
    ("CommandReply", p.CommandReply),
    ("Telemetry", p.Telemetry),
    ("WorldMessage", p.WorldMessage),
    ("WorldReply", p.WorldReply),
    ("Operations (the `op` of a Request)", OperatorOp),
    ("MapSnapshot", mf.MapSnapshot),
    ("MapDelta", mf.MapDelta),
    ("SimStatus", mf.SimStatus),
]


def render() -> str:
    out = [PROSE]
    for title, model in MODELS:
        out.append(f"\n### {title}\n")
        if model is None:
            continue
        schema = TypeAdapter(model).json_schema()
        out.append("```json\n" + json.dumps(schema, indent=1, sort_keys=False) + "\n```\n")
    return "".join(out)


if __name__ == "__main__":
    sys.stdout.write(render())
