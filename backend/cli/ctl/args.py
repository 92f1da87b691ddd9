"""`missionctl ctl`: every mission operation, scriptable against a running server.

    missionctl ctl [--connect ENDPOINT] [--json] [--timeout S] [--client-id ID]
                   [--expect-revision N] [--request-id ID] OP ...

The common options may be given before or after OP. One invocation opens one
connection (a `MissionClient`, subscribed to telemetry only for `robots`),
does one thing and always closes the connection.

Operations
  state [ROBOT...] [--nowcast]
                              the mission: per robot its skills (glyph, id,
                              label, skill, parameters that differ from the
                              library defaults), barriers, markers, revision;
                              --nowcast: each robot's probable present (≈:
                              skill, progress, position, battery) predicted
                              from its last report, and that report's age
  robots                      presence, type, manifest (modules, skills) and,
                              when a robot publishes it within ~5 s, battery,
                              link quality and activity
  robots add NAME [--type T]  add a robot that asks to join (announced), or one to come
  robots retire NAME --reason TEXT
                              no new syncs; its queue taken back; its plan to reassign
  reassign ID... --to ROBOT | reassign --from ROBOT --to ROBOT
                              give idle skills (or a robot's whole plan) to a robot
                              that offers them; each one that cannot move says why
  suggest SKILL_OR_ID...      the robots that can take these skills (or a new one of
                              this library skill), earliest predicted end first, with
                              the battery left (the forecast, with telemetry)
  add ROBOT SKILL [--param NAME=VALUE]... [--label TEXT] [--at INDEX] [POLICY]
  delete ID...
  move ID INDEX               INDEX within the unsynchronized section (0 = first)
  edit ID [--label TEXT] [--param NAME=VALUE]... [--unbind NAME]... [POLICY]
  sync ROBOT [--through ID]            [--expire D] [--wait [S]]
  unsync ROBOT [--from ID]             [--expire D] [--wait [S]]
  run|pause|stop|reset (ROBOT | --all) [--expire D] [--wait [S]]
  retry ID                             [--expire D] [--wait [S]]
  pending [ROBOT...]          commands to robots not settled yet: number,
                              robot, what, state, age, expiry, and the stage
                              it waits for with its due time (--json: every
                              stage: queued, sent, received, started,
                              completed, each with state, at, due, tolerance)
  cancel COMMAND [--wait [S]] withdraw a pending command (final while it is
                              queued; once sent, the robot's answer decides)
  questions [ROBOT...]        robots' open questions: text, numbered choices, and
                              how long until the default applies on board
                              (mission time); --json: every field
  answer Q CHOICE [--wait [S]]
                              answer question Q with one of its choices (or its
                              number): a command up the robot's uplink
  wait COMMAND [--until received|started|completed] [--grace D] [--max-wait S]
                              until the command's stage is reached (exit 0),
                              never will be (1: refused, expired, a skill
                              failed) or is overdue: past its due time and
                              tolerance, plus D (4)
  barrier ID ID... [--barrier-timeout D] [--on-timeout continue|halt]
  barrier BARRIER_ID [--barrier-timeout D] [--on-timeout continue|halt]
                              idle skills start together; a robot waits for its
                              partners D of mission time (off: for ever), then starts
                              alone (continue) or fails (halt); one barrier's id:
                              change its wait (its skills idle), unnamed ones kept
  unbarrier BARRIER_ID
  marker add NAME (--pose P | --position P | --area A) [--description TEXT]
  marker move NAME (--pose P | --position P | --area A)
  marker rename NAME NEW_NAME
  marker delete NAME
  load FILE [--keep-state]    validated here first (file:line:col issues, exit 2); as
                              a plan: unfinished skills idle (--keep-state: the
                              file's statuses; refused while its robots are online)
  save FILE [--plan] [--library PATH]
                              the mission with its statuses (--plan: every skill
                              idle); loads from where it is written (the library
                              is written beside it when the reference would break)
  new [NAME]                  an empty mission with the same robots
  undo | redo                 your own (same --client-id) edits of the plan
  watch [--count N]           one line per change until Ctrl-C (or N batches)
  check [ROBOT...]            the plan checks (energy, coverage, barriers, terrain,
                              parameters), computed with the robots' telemetry and
                              the simulator's map when they answer; exit 1 while
                              an error is not waived
  waive CHECK_ID --reason TEXT   let a finding's skills be synchronized anyway
  unwaive CHECK_ID            withdraw a waiver
  timeline                    each skill's predicted start and end, barrier waits,
                              battery, spans out of coverage, and the plan's end
  history [--robot R] [--user U] [--since T] [--limit N]
                              who did what, from the server's journal: every
                              operation (with its user and console), robot
                              report and answer, oldest first (the newest N)

Parameter values (--param NAME=VALUE)
  VALUE is a YAML scalar or flow YAML: `speed=0.4`, `filter=near_infrared`,
  `goal={x: 3, y: 4, yaw: 0}` (quote it for the shell), `sensors=[lidar]`.
  `NAME=@MARKER` binds a pose/position/area parameter to a marker (the value
  follows the marker while the skill is idle); for a `marker` parameter it
  names the marker. An empty VALUE (`speed=`) means the library default.
  `--unbind NAME` (edit) keeps the current value but drops the binding.
  POLICY: --retries N, --pause-out-of-comms / --no-pause-out-of-comms,
  --recharge-below F (0..1, or `off`); contingencies: --skill-timeout 10m,
  --not-after 'sim 2:00:00' (a mission-clock time; 2h: two hours of sim time),
  --on-failure / --on-timeout halt|skip|continue|goto:MARKER|
  fallback:SKILL[+SKILL]; on edit, unnamed policies are kept.

Geometry
  --pose x,y[,z[,roll,pitch,yaw]] or a flow mapping '{x: 1, y: 2, yaw: 90}'
  Angles (roll, pitch, yaw; a parameter in rad) are in degrees, as ctl prints
  them (heading 0 = east, counter-clockwise); 30deg and 0.52rad say their
  unit. Files and --json keep radians.
  --position x,y[,z] or '{x: 1, y: 2}'
  --area "x,y x,y x,y ..." (at least 3 points; ';' also separates points)
  A value starting with '-' must be attached: --pose=-3,4. `marker move` with
  --position on a pose marker keeps the marker's orientation.

Connection and identity
  --connect defaults to $MISSIONCTL_CONNECT, else tcp/127.0.0.1:7447 (repeat
  it, or separate endpoints with commas, to give several).
  --client-id defaults to $MISSIONCTL_CLIENT_ID, else `ctl-USER@HOST`: stable
  across invocations, so `ctl undo` undoes what the previous `ctl add` did.
  Every request gets a fresh unique request id; after a timeout, retry with
  `--request-id` (the id is in the message) and the server applies it once.
  --expect-revision N refuses the operation if what it touches changed after
  revision N (optimistic concurrency).

Commands to robots (protocol 2)
  An operation on a robot never waits for the robot: it queues a command in
  the robot's uplink and returns at once (`queued for lru1, command 17: sync
  lru1-4, lru1-5`); the server sends it when the robot can hear it, minutes
  later if need be, and the robot's answer (what it actually did) changes
  the mission. --expire D (30m, 2h, 90s, never): the robot never applies it
  later (default: the server's --command-expiry). --wait [S] waits up to S
  seconds (default 600) for the robot's answer: exit 0 applied, 1 refused,
  expired or cancelled, 3 not answered in time (the command stays pending:
  `ctl pending`, `ctl cancel N`) or server unreachable.

Output
  One line per success (`added lru1-7 (drive_to) to lru1 at revision 12`) and
  the server's notes as `note: ...`. With --json, exactly one JSON object on
  stdout: for operations {"ok": true, "op", "revision", "value", "notes",
  "duplicate"}; `state --json` is the state itself ({"revision", "name",
  "library", "robots", "tasks", "barriers", "markers"}); `watch --json` prints
  one object per line. Failures print on stderr (one line; a usage error
  also the usage) and, with --json, exactly one {"ok": false, "code",
  "message", ...} on stdout, usage errors included. "code" is bad_input or
  bad_file (exit 2; bad_file lists "issues" as file:line:col), the server's
  refusal (exit 1: stale, not_idle, unknown_skill, journal_failed, ..., with
  "robot", "skill", "param" when known), or unreachable, timeout,
  protocol_mismatch (exit 3). With "maybe_applied": true (a timeout, or a
  server gone mid-request) the operation may have been applied: run it again
  with --request-id REQUEST_ID (given in "request_id"), it is applied once.

Exit codes: 0 ok, 1 refused by the server, 2 bad usage or input (nothing is
sent), 3 server unreachable, not answering in time, or speaking another
protocol version; `wait` only: 4 the stage is overdue. Never a traceback
(MISSIONCTL_DEBUG=1 shows one for unexpected errors).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import Any

from backend.cli.ctl.contingency import add_after_args, add_barrier_args
from backend.cli.ctl.contingency import add_options as add_contingency_options
from backend.cli.ctl.questions import answer_arguments, questions_arguments
from backend.cli.ctl.team import reassign_arguments, robots_arguments, suggest_arguments
from backend.cli.parser import Parser
from backend.transport.login import add_login_arguments

DEFAULT_CONNECT = "tcp/127.0.0.1:7447"
DEFAULT_TIMEOUT = 10.0

CONTROL_OPS = ("run", "pause", "stop", "reset")  # on one robot or --all (see OPERATIONS)
# operations that queue commands to robots (the robot's answer comes later: --wait)
ROBOT_OPS = ("sync", "unsync", *CONTROL_OPS, "retry", "cancel", "answer")


def _recharge(text: str) -> float | None:
    if text.strip().lower() in ("off", "none", "no", "never"):
        return None
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a battery fraction 0..1 or 'off', got {text!r}"
        ) from None
    if not (0.0 <= v <= 1.0):
        raise argparse.ArgumentTypeError(
            f"expected a battery fraction between 0 and 1, got {text!r}"
        )
    return v


def _nonneg_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected 0 or more, got {v}")
    return v


DEFAULT_WAIT = 600.0  # --wait without a value: seconds


def _duration(text: str) -> float:
    from backend.cli.ctl.values import parse_duration

    return parse_duration(text)


def _wait_and_expire(p: argparse.ArgumentParser, *, expire: bool = True) -> None:
    g = p.add_argument_group("the robot's answer")
    g.add_argument(
        "--wait",
        nargs="?",
        const=DEFAULT_WAIT,
        type=_positive_float,
        metavar="S",
        help=f"wait up to S seconds (default {DEFAULT_WAIT:g}) for the robot's answer",
    )
    if expire:
        g.add_argument(
            "--expire",
            type=_duration,
            metavar="D",
            help="the robot never applies it after D (30m, 2h, 90s; never); default: the server's",
        )


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return v


def _common(p: argparse.ArgumentParser, *, top: bool) -> None:
    """Options accepted before and after OP (after OP they override)."""
    d = (lambda v: v) if top else (lambda v: argparse.SUPPRESS)
    g = p.add_argument_group("connection and output")
    g.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        default=d(None),
        help=f"mission server endpoint (default: $MISSIONCTL_CONNECT or {DEFAULT_CONNECT}); "
        "repeatable",
    )
    g.add_argument(
        "--json",
        action="store_true",
        default=d(False),
        help="print one JSON object (watch: one per line)",
    )
    g.add_argument(
        "--timeout",
        type=_positive_float,
        metavar="S",
        default=d(DEFAULT_TIMEOUT),
        help=f"seconds to wait for the server (default {DEFAULT_TIMEOUT:g})",
    )
    g.add_argument(
        "--client-id",
        metavar="ID",
        default=d(None),
        help="client id (default: $MISSIONCTL_CLIENT_ID or ctl-USER@HOST; "
        "undo/redo are per client id)",
    )
    g.add_argument(
        "--expect-revision",
        type=_nonneg_int,
        metavar="N",
        default=d(None),
        help="refuse if what the operation touches changed after revision N",
    )
    g.add_argument(
        "--request-id",
        metavar="ID",
        default=d(None),
        help="request id (default: a fresh one); reuse it to retry safely after a timeout",
    )
    add_login_arguments(p.add_argument_group("login and TLS (docs/security.md)"), suppress=not top)


def _policies(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("policies")
    g.add_argument(
        "--retries",
        type=_nonneg_int,
        metavar="N",
        help="autonomous retries after a failure (0..20)",
    )
    g.add_argument(
        "--pause-out-of-comms",
        dest="pause_out_of_comms",
        action="store_const",
        const=True,
        help="pause while out of communication range",
    )
    g.add_argument(
        "--no-pause-out-of-comms", dest="pause_out_of_comms", action="store_const", const=False
    )
    g.add_argument(
        "--recharge-below",
        type=_recharge,
        metavar="F",
        default=argparse.SUPPRESS,
        help="return to recharge below this battery fraction (0..1, or 'off')",
    )
    add_contingency_options(p.add_argument_group("contingency (applied on board)"))


def _geometry(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument(
        "--pose",
        metavar="P",
        help="x,y[,z[,roll,pitch,yaw]] or '{x: 1, y: 2, yaw: 90}' (angles in degrees, or 1.57rad)",
    )
    g.add_argument("--position", metavar="P", help="x,y[,z] or '{x: 1, y: 2}'")
    g.add_argument("--area", metavar="A", help='polygon "x,y x,y x,y ..." (3 points or more)')


def _param_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--param", action="append", metavar="NAME=VALUE", help="parameter value (YAML) or @MARKER"
    )


# ---------------------------------------------------------------- one per operation


def _nothing(p: argparse.ArgumentParser) -> None:
    pass


def _state(p: argparse.ArgumentParser) -> None:
    p.add_argument("robots", nargs="*", metavar="ROBOT", help="only these robots")


def _state_op(p: argparse.ArgumentParser) -> None:
    _state(p)
    p.add_argument(
        "--nowcast",
        action="store_true",
        help="also each robot's probable present (≈): skill and progress, position, battery, "
        "predicted from its last report, its plan and the time since",
    )


def _add(p: argparse.ArgumentParser) -> None:
    p.add_argument("robot", metavar="ROBOT")
    p.add_argument("skill", metavar="SKILL")
    _param_option(p)
    p.add_argument("--label", metavar="TEXT")
    p.add_argument(
        "--at",
        type=int,
        metavar="INDEX",
        help="position in the unsynchronized section (default: end)",
    )
    _policies(p)


def _ids(p: argparse.ArgumentParser) -> None:
    p.add_argument("ids", nargs="+", metavar="ID")


def _id(p: argparse.ArgumentParser) -> None:
    p.add_argument("id", metavar="ID")


def _move(p: argparse.ArgumentParser) -> None:
    p.add_argument("id", metavar="ID")
    p.add_argument("index", type=int, metavar="INDEX", help="0 = first unsynchronized skill")


def _edit(p: argparse.ArgumentParser) -> None:
    p.add_argument("id", metavar="ID")
    p.add_argument("--label", metavar="TEXT")
    _param_option(p)
    p.add_argument(
        "--unbind",
        action="append",
        metavar="NAME",
        help="drop a parameter's marker binding (keeps its value)",
    )
    _policies(p)


def _sync(p: argparse.ArgumentParser) -> None:
    p.add_argument("robot", metavar="ROBOT")
    p.add_argument("--through", metavar="ID", help="last skill to synchronize")
    _wait_and_expire(p)


def _unsync(p: argparse.ArgumentParser) -> None:
    p.add_argument("robot", metavar="ROBOT")
    p.add_argument("--from", dest="from_id", metavar="ID", help="first queued skill to take back")
    _wait_and_expire(p)


def _control(p: argparse.ArgumentParser) -> None:
    p.add_argument("robot", nargs="?", metavar="ROBOT")
    p.add_argument("--all", action="store_true", help="every robot")
    _wait_and_expire(p)


def _retry(p: argparse.ArgumentParser) -> None:
    _id(p)
    _wait_and_expire(p)


def _cancel(p: argparse.ArgumentParser) -> None:
    p.add_argument("command", type=_command_number, metavar="COMMAND", help="its number")
    _wait_and_expire(p, expire=False)


DEFAULT_MAX_WAIT = 600.0  # `wait`: seconds for a stage that has no due


def _wait_stage(p: argparse.ArgumentParser) -> None:
    p.add_argument("command", type=_command_number, metavar="COMMAND", help="its number")
    p.add_argument(
        "--until",
        choices=("received", "started", "completed"),
        default="received",
        help="the stage to wait for (default: received)",
    )
    p.add_argument(
        "--grace",
        type=_duration,
        default=0.0,
        metavar="D",
        help="more tolerance past the stage's due before it counts as overdue (90s, 5m)",
    )
    p.add_argument(
        "--max-wait",
        type=_positive_float,
        default=DEFAULT_MAX_WAIT,
        metavar="S",
        help=f"seconds to wait when the stage has no due (default {DEFAULT_MAX_WAIT:g})",
    )


def _command_number(text: str) -> int:
    try:
        v = int(text.removeprefix("command").strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a command number, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"command numbers start at 1, got {v}")
    return v


def _unbarrier(p: argparse.ArgumentParser) -> None:
    p.add_argument("barrier", metavar="BARRIER_ID")


def _marker_add(p: argparse.ArgumentParser) -> None:
    _geometry(p)
    p.add_argument("--description", default="", metavar="TEXT")


def _marker_rename(p: argparse.ArgumentParser) -> None:
    p.add_argument("new_name", metavar="NEW_NAME")


Arguments = Callable[[argparse.ArgumentParser], None]

# `marker ACTION NAME ...`: action -> (help, its arguments after NAME)
MARKER_ACTIONS: dict[str, tuple[str, Arguments]] = {
    "add": ("add a pose, position or area marker", _marker_add),
    "move": (
        "give a marker a new pose, position or area (idle bound skills follow)",
        _geometry,
    ),
    "rename": ("rename a marker (bindings follow)", _marker_rename),
    "delete": ("delete a marker (not while a synchronized skill uses it)", _nothing),
}


def _marker(p: argparse.ArgumentParser) -> None:
    actions = p.add_subparsers(dest="marker_op", metavar="ACTION")
    actions.required = True
    for name, (help, arguments) in MARKER_ACTIONS.items():
        sp = actions.add_parser(name, help=help, description=help)
        _common(sp, top=False)
        sp.add_argument("name", metavar="NAME")
        arguments(sp)


def _save(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE")
    p.add_argument(
        "--plan",
        action="store_true",
        help="save the plan: every skill idle (default: the statuses and the log as they are)",
    )
    p.add_argument(
        "--library",
        metavar="PATH",
        help="the skill library file to reference, written relative to FILE (default: the "
        "server's reference when it leads to its library from there, else FILE's name with "
        ".library.yaml, written beside it)",
    )


def _load(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE")
    p.add_argument(
        "--keep-state",
        action="store_true",
        help="keep the file's statuses (refused while a robot of the mission is online; "
        "default: a plan, every unfinished skill idle, the log kept)",
    )


def _new(p: argparse.ArgumentParser) -> None:
    p.add_argument("name", nargs="?", default="mission", metavar="NAME")


def _check_id(p: argparse.ArgumentParser) -> None:
    p.add_argument("check", metavar="CHECK_ID", help="a finding's id, as `ctl check` prints it")


def _waive(p: argparse.ArgumentParser) -> None:
    _check_id(p)
    p.add_argument("--reason", required=True, metavar="TEXT", help="why (journaled, in every log)")


def _history(p: argparse.ArgumentParser) -> None:
    p.add_argument("--robot", metavar="R", help="only changes concerning robot R")
    p.add_argument(
        "--user",
        dest="history_user",
        metavar="U",
        help="only operations of user U (to log in, give --user before `history`)",
    )
    p.add_argument(
        "--since",
        type=_since,
        metavar="T",
        help="only changes since T: 30m (ago), 14:32 (today), 2030-07-01T14:32",
    )
    p.add_argument(
        "--limit",
        type=_history_limit,
        default=200,
        metavar="N",
        help="the newest N matching changes (default 200, at most 10000)",
    )


def _since(text: str) -> Any:
    from backend.cli.ctl.values import parse_since

    return parse_since(text)


def _history_limit(text: str) -> int:
    n = _nonneg_int(text)
    if not 1 <= n <= 10_000:
        raise argparse.ArgumentTypeError(f"expected 1 to 10000, got {n}")
    return n


def _watch(p: argparse.ArgumentParser) -> None:
    p.add_argument("--count", type=_nonneg_int, metavar="N", help="stop after N change batches")


# ctl's operations, in the order `ctl --help` lists them: name -> (help, its arguments).
# Each also takes the common options (_common).
OPERATIONS: dict[str, tuple[str, Arguments]] = {
    "state": ("print the mission: robots, skills, barriers, markers, revision", _state_op),
    "robots": (
        "robot presence, type, manifest and telemetry; add or retire a robot",
        lambda p: robots_arguments(p, _common),
    ),
    "add": ("add a skill to a robot's unsynchronized section", _add),
    "delete": ("delete idle skills", _ids),
    "move": ("move an idle skill within its robot's unsynchronized section", _move),
    "edit": ("change the label, parameters, bindings or policies of an idle skill", _edit),
    "sync": ("send a robot its unsynchronized skills (all, or through ID)", _sync),
    "unsync": ("take queued skills back from a robot (all, or from ID on)", _unsync),
    "run": ("start or resume execution, on one robot or --all", _control),
    "pause": ("pause the running skill, on one robot or --all", _control),
    "stop": ("stop the active skill (it returns to the queue), on one robot or --all", _control),
    "reset": ("stop and unsynchronize everything queued, on one robot or --all", _control),
    "retry": ("retry a failed skill (a new attempt right after it)", _retry),
    "pending": ("commands to robots not settled yet (age, expiry)", _state),
    "cancel": ("withdraw a pending command to a robot", _cancel),
    "wait": ("wait for a command's stage: received, started or completed", _wait_stage),
    "barrier": (
        "make idle skills of different robots start together, or change a barrier's timeout",
        add_barrier_args,
    ),
    "questions": ("robots' open questions and when their defaults apply", questions_arguments),
    "answer": (
        "answer a robot's question with one of its choices",
        lambda p: answer_arguments(p, _wait_and_expire),
    ),
    "after": ("start an idle skill only once another robot's skill succeeded", add_after_args),
    "unbarrier": ("remove a barrier", _unbarrier),
    "reassign": ("give idle skills, or a robot's plan, to another robot", reassign_arguments),
    "suggest": ("rank the robots that can take skills: forecast end, battery", suggest_arguments),
    "marker": ("add, move, rename or delete a marker", _marker),
    "load": ("replace the mission with a mission file (validated here first)", _load),
    "save": ("write the mission to a YAML file", _save),
    "new": ("start an empty mission with the same robots", _new),
    "undo": ("undo your last edit of the plan", _nothing),
    "redo": ("redo what you undid last", _nothing),
    "watch": ("print changes as they happen, one line each, until Ctrl-C", _watch),
    "check": ("run the plan checks; exit 1 while an error is not waived", _state),
    "waive": ("let the skills of a plan check's finding be synchronized anyway", _waive),
    "unwaive": ("withdraw a waiver", _check_id),
    "timeline": ("print the predicted timeline of the plan", _nothing),
    "history": ("who did what: the server's journal, filtered (audit)", _history),
}


def prepare_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add `ctl` to missionctl's sub-commands."""
    p = subparsers.add_parser(
        "ctl",
        help="run mission operations against a running server (scriptable, --json)",
        description=__doc__.split("\n\n", 1)[1] if __doc__ else None,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _common(p, top=True)
    ops = p.add_subparsers(dest="op", metavar="OP")
    for name, (help, arguments) in OPERATIONS.items():
        # history's own --user (a filter) replaces the login's: log in before OP
        resolve = "resolve" if name == "history" else "error"
        sp = ops.add_parser(name, help=help, description=help, conflict_handler=resolve)
        _common(sp, top=False)
        arguments(sp)
    return p


def build_parser() -> argparse.ArgumentParser:
    """A stand-alone `missionctl` parser with only `ctl` (tests)."""
    top = Parser(prog="missionctl")
    sub = top.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    prepare_parser(sub)
    return top


def wants_json(argv: list[str]) -> bool:
    """`missionctl ARGV...` is `ctl ... --json ...` (before any `--`)."""
    if not argv or argv[0] != "ctl":
        return False
    args = argv[1 : argv.index("--")] if "--" in argv else argv[1:]
    return "--json" in args


def parse_args(argv: list[str]) -> argparse.Namespace:
    """`missionctl ctl ARGV...` parsed (argparse errors exit 2)."""
    parser = build_parser()
    Parser.json_errors = wants_json(["ctl", *argv])
    return parser.parse_args(["ctl", *argv])
